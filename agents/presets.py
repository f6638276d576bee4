"""Named agent presets: every curve of the paper's Figure 2, plus the baselines.

`oracle_rh` etc. follow the paper's seed experiments: λ_h = λ_s = 10, each bonus and the extrinsic
reward divided by its own rolling std (appendix C).
"""

from __future__ import annotations

import dataclasses

from hyperstate.agents.config import AgentConfig, BonusConfig, PPOConfig

STATE_BONUS = BonusConfig(input="state")  # state_keys="task": the task's position keys
HYPERSTATE_BONUS = BonusConfig(input="hyperstate")
# The reference scales the belief oracle's RND prior by 5 instead of 10.
ORACLE_HYPERSTATE_BONUS = dataclasses.replace(HYPERSTATE_BONUS, prior_scale=5.0)

PRESETS: dict[str, AgentConfig] = {
    "ppo": AgentConfig(belief="none"),
    "rl2": AgentConfig(belief="recurrent", ppo=PPOConfig(lr=3e-4)),
    "oracle": AgentConfig(belief="oracle"),
    "oracle_rh": AgentConfig(belief="oracle", bonuses=(ORACLE_HYPERSTATE_BONUS,)),
    "oracle_rs": AgentConfig(belief="oracle", bonuses=(STATE_BONUS,)),
    "oracle_ensemble_rh": AgentConfig(
        belief="oracle", bonuses=(dataclasses.replace(ORACLE_HYPERSTATE_BONUS, kind="ensemble_rnd", ensemble_size=5),)
    ),
    "varibad": AgentConfig(belief="varibad"),
    "varibad_rh": AgentConfig(belief="varibad", bonuses=(HYPERSTATE_BONUS,)),
    "hyperx": AgentConfig(belief="varibad", bonuses=(HYPERSTATE_BONUS, STATE_BONUS)),
    "task_supervised": AgentConfig(belief="task_supervised"),
    # Not a meta-learner: knows the task. evaluation/run.py trains it as the reference for regret.
    "task_aware": AgentConfig(belief="task_aware"),
}


def list_presets() -> list[str]:
    return sorted(PRESETS)


def get_preset(name: str) -> AgentConfig:
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown agent preset {name!r}; presets: {', '.join(sorted(PRESETS))}") from None
