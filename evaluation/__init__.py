"""hyperstate.evaluation: train and deploy grids of agents × tasks × seeds; report online return.

Entry point: `python evaluation/run.py --help`. Bring your own agent with `register_agent(name)` (the
benchmarkable-agent protocol is in `hyperstate.evaluation.protocol`; docs/new_agent.md has examples).
"""

from hyperstate.evaluation.protocol import (
    BenchmarkAgent,
    agent_names,
    load_agent,
    make_agent,
    register_agent,
    unregister_agent,
)

__all__ = ["BenchmarkAgent", "agent_names", "load_agent", "make_agent", "register_agent", "unregister_agent"]
