"""hyperstate.agents: PPO agents assembled from belief and bonus components.

agent = agents.make("hyperx", **{"ppo.num_envs": 32})
log = agent.train("cheetah_dir_sparse", frames=1_000_000, seed=0, checkpoint_dir="runs/x")
action, state = agent.act(obs)                      # deployment, from the prior belief

Components are chosen by name from registries, the built-in ones included; bring your own with
`register_belief(name)` / `register_bonus(kind)` (class decorators) and name a config with
`register_preset(name, config)` (see docs/new_agent.md).
"""

from __future__ import annotations

from typing import Any

from hyperstate.agents.agent import Agent, AgentState
from hyperstate.agents.beliefs import Belief, Trajectories, Transition, list_beliefs, register_belief
from hyperstate.agents.bonuses import Bonus, BonusInput, list_bonuses, register_bonus
from hyperstate.agents.config import (
    RUNTIME_FIELDS,
    AgentConfig,
    BonusConfig,
    PPOConfig,
    RecurrentConfig,
    VAEConfig,
    agent_settings,
    apply_overrides,
    budget_dependence,
    check_budget,
)
from hyperstate.agents.presets import (
    GRID_PRESETS,
    PRESETS,
    check_components,
    get_preset,
    list_presets,
    register_preset,
    unregister_preset,
)


def make(preset: str, **overrides: Any) -> Agent:
    """The agent of a named preset, with config overrides (dotted names or nested dicts)."""
    config = apply_overrides(get_preset(preset), overrides)
    check_components(config)
    return Agent(config, name=preset)


__all__ = [
    "GRID_PRESETS",
    "PRESETS",
    "RUNTIME_FIELDS",
    "Agent",
    "AgentConfig",
    "AgentState",
    "Belief",
    "Bonus",
    "BonusConfig",
    "BonusInput",
    "PPOConfig",
    "RecurrentConfig",
    "Trajectories",
    "Transition",
    "VAEConfig",
    "agent_settings",
    "apply_overrides",
    "budget_dependence",
    "check_budget",
    "get_preset",
    "list_beliefs",
    "list_bonuses",
    "list_presets",
    "make",
    "register_belief",
    "register_bonus",
    "register_preset",
    "unregister_preset",
]
