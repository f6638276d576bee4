"""hyperstate.agents: PPO agents assembled from belief and bonus components.

agent = agents.make("hyperx", **{"ppo.num_envs": 32})
log = agent.train("cheetah_dir_sparse", frames=1_000_000, seed=0, checkpoint_dir="runs/x")
action, state = agent.act(obs)                      # deployment, from the prior belief
"""

from __future__ import annotations

from typing import Any

from hyperstate.agents.agent import Agent, AgentState
from hyperstate.agents.config import AgentConfig, BonusConfig, PPOConfig, RecurrentConfig, VAEConfig, apply_overrides
from hyperstate.agents.presets import PRESETS, get_preset, list_presets


def make(preset: str, **overrides: Any) -> Agent:
    """The agent of a named preset, with config overrides (dotted names or nested dicts)."""
    config = apply_overrides(get_preset(preset), overrides)
    return Agent(config, name=preset)


__all__ = [
    "PRESETS",
    "Agent",
    "AgentConfig",
    "AgentState",
    "BonusConfig",
    "PPOConfig",
    "RecurrentConfig",
    "VAEConfig",
    "apply_overrides",
    "get_preset",
    "list_presets",
    "make",
]
