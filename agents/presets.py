"""Named agent presets: every curve of the paper's Figure 2, plus the baselines, in three families.

- `hyperx`, `oracle_rh`, ...: the validated agents, those behind the committed results (docs/agents.md lists
  every difference from the other two families, with its evidence).
- `<name>_paper`: the seed paper's literal settings (appendix C): λ_h = λ_s = 10, CleanRL's PPO and network.
- `hyperx_icml`, `oracle_rh_icml`: the reference code's ICML configurations.
"""

from __future__ import annotations

import dataclasses
import inspect

from hyperstate.agents.config import AgentConfig, BonusConfig, PPOConfig, VAEConfig
from hyperstate.registry import Registry

# The seed paper's literal settings (appendix C) and this project's first defaults: CleanRL's PPO and network,
# the learning rate annealed over the run's budget, RND predictors trained once per iteration on 10,000 inputs.
PAPER_PPO = PPOConfig(
    lr_anneal_frames=None,
    value_loss="mse",
    minibatch_unit="envs",
    advantage_norm="minibatch",
    sampled_action_cost=0.0,
    network="cleanrl",
)
_PAPER_RND = {"buffer_size": 10_000, "updates_per_iteration": 1}

# Bonuses of the validated presets. state_keys="task": the task's position keys (the cheetah's x-position).
HYPERSTATE_BONUS = BonusConfig(input="hyperstate")
STATE_BONUS = BonusConfig(input="state")

# The reference code's ICML configurations for sparse cheetah-dir (config/sparse_cheetah_dir/cds_hyperx.py and
# cds_belief_oracle.py): raw RND inputs, prior weights (not output) scaled, one predictor update per
# iteration, bonuses annealed over the run; PPO with transition minibatches, whole-batch advantage
# normalisation, the clipped Huber value loss, and the control cost charged on the sampled action.
ICML_PPO = dataclasses.replace(
    PAPER_PPO,
    minibatch_unit="transitions",
    advantage_norm="batch",
    value_loss="clipped_huber",
    sampled_action_cost=0.05,
)
_ICML_RND = BonusConfig(input="hyperstate", input_norm="none", prior_scaling="weights", **_PAPER_RND)

# The validated agents: the defaults of PPOConfig and BonusConfig, which are the agents of the committed
# turn-around grid (docs/results/fig2_turnaround, tested field for field against its records).
_BUILT_IN: dict[str, AgentConfig] = {
    "ppo": AgentConfig(belief="none"),
    # RL²'s GRU is trained through time by the policy's loss: minibatches of whole env sequences.
    "rl2": AgentConfig(belief="recurrent", ppo=PPOConfig(lr=3e-4, minibatch_unit="envs")),
    "oracle": AgentConfig(belief="oracle"),
    # λ_h = 20: with the paper's 10 the oracle ran one way on cheetah_dir_sparse in 3 of 3 seeds (docs/agents.md).
    "oracle_rh": AgentConfig(belief="oracle", bonuses=(dataclasses.replace(HYPERSTATE_BONUS, weight=20.0),)),
    "oracle_rs": AgentConfig(belief="oracle", bonuses=(STATE_BONUS,)),
    "oracle_ensemble_rh": AgentConfig(
        belief="oracle", bonuses=(dataclasses.replace(HYPERSTATE_BONUS, kind="ensemble_rnd", ensemble_size=5),)
    ),
    "varibad": AgentConfig(belief="varibad"),
    "varibad_rh": AgentConfig(belief="varibad", bonuses=(HYPERSTATE_BONUS,)),
    "hyperx": AgentConfig(belief="varibad", bonuses=(HYPERSTATE_BONUS, STATE_BONUS)),
    "task_supervised": AgentConfig(belief="task_supervised"),
    # Not a meta-learner: knows the task. evaluation/run.py trains it as the reference for regret.
    "task_aware": AgentConfig(belief="task_aware"),
    # HyperX as in the reference code: hyper-state RND x0.1 + VAE-error bonus x1.0, no state bonus, and the
    # reference's VAE buffer of 10,000 trajectories (the other presets keep 1,000), from which the RND's
    # predictor draws its inputs, latents recomputed by the current encoder.
    "hyperx_icml": AgentConfig(
        belief="varibad",
        ppo=ICML_PPO,
        vae=VAEConfig(buffer_trajectories=10_000),
        bonuses=(
            dataclasses.replace(_ICML_RND, weight=0.1, train_on="replay"),
            BonusConfig(kind="vae_error", input="belief", weight=1.0, **_PAPER_RND),
        ),
        anneal_bonus=True,
    ),
    # The belief oracle as in the reference code: hyper-state RND x5 (prior weights x5), clipped at 10,
    # a buffer of 1e7 inputs.
    "oracle_rh_icml": AgentConfig(
        belief="oracle",
        ppo=ICML_PPO,
        bonuses=(dataclasses.replace(_ICML_RND, weight=5.0, prior_scale=5.0, clip=10.0, buffer_size=10_000_000),),
        anneal_bonus=True,
    ),
}

# The presets of the committed turn-around grid, the agents the project's results are about.
GRID_PRESETS = ("oracle", "oracle_rh", "oracle_rs", "varibad", "varibad_rh", "hyperx", "task_aware")


def paper_variant(config: AgentConfig) -> AgentConfig:
    """`config` with the seed paper's literal PPO, network and RND-training settings (and λ_h = 10)."""
    bonuses = tuple(
        dataclasses.replace(b, weight=10.0 if b.kind == "rnd" else b.weight, **_PAPER_RND) for b in config.bonuses
    )
    ppo = dataclasses.replace(PAPER_PPO, lr=config.ppo.lr, minibatch_unit=config.ppo.minibatch_unit)
    if config.belief != "recurrent":
        ppo = dataclasses.replace(ppo, minibatch_unit=PAPER_PPO.minibatch_unit)
    return dataclasses.replace(config, ppo=ppo, bonuses=bonuses)


_BUILT_IN.update({f"{name}_paper": paper_variant(_BUILT_IN[name]) for name in GRID_PRESETS})
PRESETS: Registry[AgentConfig] = Registry("agent preset", "presets")
for _name, _config in _BUILT_IN.items():
    PRESETS.add(_name, _config, owner=__name__)


def register_preset(name: str, config: AgentConfig) -> AgentConfig:
    """Names an `AgentConfig` (built-in or your own components) so that `agents.make(name)`,
    `evaluation/run.py --agents name` and `--config` tables use it. Returns the config."""
    PRESETS.check_free(name)
    if not isinstance(config, AgentConfig):
        raise TypeError(f"preset {name!r} must be an agents.AgentConfig, got {type(config).__name__}")
    check_components(config)
    caller = inspect.currentframe().f_back
    return PRESETS.add(name, config, owner=caller.f_globals.get("__name__", "?") if caller else "?")


def unregister_preset(name: str) -> None:
    """Removes a registered preset (for tests and interactive sessions)."""
    PRESETS.remove(name)


def check_components(config: AgentConfig) -> None:
    """ValueError (with did-you-mean) if the config names a belief or bonus kind nobody registered."""
    from hyperstate.agents.beliefs import belief_class
    from hyperstate.agents.bonuses import bonus_class

    belief_class(config.belief)
    for bonus in config.bonuses:
        bonus_class(bonus.kind)


def list_presets() -> list[str]:
    return PRESETS.names()


def get_preset(name: str) -> AgentConfig:
    return PRESETS.lookup(name)
