"""Agent configuration: frozen dataclasses whose defaults follow the paper / reference code.

Overrides use dotted names (`"ppo.lr"`, `"vae.latent_dim"`, `"bonuses.0.weight"`) or nested dicts;
an unknown name is a `ValueError` that lists the valid ones.
"""

from __future__ import annotations

import dataclasses
import difflib
from typing import Any


def _check_choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ValueError(f"{name} must be one of {', '.join(map(repr, choices))}; got {value!r}")


@dataclasses.dataclass(frozen=True)
class PPOConfig:
    """PPO hyperparameters (reference: variBAD/HyperX on cheetah-dir)."""

    num_envs: int = 16
    rollout_length: int = 200  # control steps per env per update; a multiple of the BAMDP length
    lr: float = 7e-4
    anneal_lr: bool = True
    # With anneal_lr, the learning rate falls linearly to 0 over this many frames; None: over the run's budget.
    # A run shorter than it ends with a positive rate and trains exactly as the first frames of a run of that
    # budget (the reference's 5e7 frames, say) would.
    lr_anneal_frames: int | None = None
    gamma: float = 0.97
    gae_lambda: float = 0.9
    clip: float = 0.1
    epochs: int = 2
    minibatches: int = 4
    entropy_coef: float = 1e-4
    value_coef: float = 0.5
    # "mse": 0.5 (V - R)^2. "clipped_huber": the reference code's 0.5 max(huber(V, R), huber(V_old + clip(V -
    # V_old, ±clip), R)).
    value_loss: str = "mse"
    # Minibatches of whole env sequences ("envs", needed by a recurrent belief such as RL²) or of transitions
    # shuffled across envs and steps ("transitions", the reference code for feed-forward policies).
    minibatch_unit: str = "envs"
    # Advantages standardised per minibatch ("minibatch") or once over the whole rollout ("batch", the reference).
    advantage_norm: str = "minibatch"
    # The task charges its control cost on the action clipped to the bounds; the reference's environment charged
    # it on the sampled action. This adds coef * (|a|^2 - |clip(a)|^2) of the sampled action a to the training
    # reward (0.05, the cheetah's control-cost weight, reproduces the reference); deployment is unaffected.
    sampled_action_cost: float = 0.0
    # None: the weighted bonuses are added to the extrinsic reward and one critic learns the sum (the paper, the
    # reference code). A discount: a second critic head learns the intrinsic return alone, discounted by it (RND's
    # two value heads, Burda et al. 2019), the bonuses are normalised by the std of their returns under it, and
    # the two streams' GAE advantages are summed. An agent without bonuses has nothing to split: one head.
    intrinsic_gamma: float | None = None

    def __post_init__(self) -> None:
        _check_choice("ppo.value_loss", self.value_loss, ("mse", "clipped_huber"))
        _check_choice("ppo.minibatch_unit", self.minibatch_unit, ("envs", "transitions"))
        _check_choice("ppo.advantage_norm", self.advantage_norm, ("minibatch", "batch"))
        _check_choice("ppo.network", self.network, ("cleanrl", "reference"))
        if self.sampled_action_cost < 0:
            raise ValueError(f"ppo.sampled_action_cost must be >= 0, got {self.sampled_action_cost}")
        if self.lr_anneal_frames is not None and self.lr_anneal_frames <= 0:
            raise ValueError(f"ppo.lr_anneal_frames must be positive or null, got {self.lr_anneal_frames}")
        if self.feature_embed_gain is not None and self.feature_embed_gain <= 0:
            raise ValueError(f"ppo.feature_embed_gain must be positive or null, got {self.feature_embed_gain}")
        if self.intrinsic_gamma is not None and not 0.0 < self.intrinsic_gamma < 1.0:
            raise ValueError(f"ppo.intrinsic_gamma must be in (0, 1) or null, got {self.intrinsic_gamma}")

    max_grad_norm: float = 0.5
    hidden: tuple[int, ...] = (128, 128)
    embed: int = 32  # state and belief features are each embedded to this size first (0: no embedding)
    # Initial weights of the belief-features embedding (actor and critic): None, PyTorch's default as in the
    # reference code (uniform, bound 1/sqrt(inputs), biases too); a gain g: orthogonal weights × g, zero biases,
    # so how far apart the policy starts to hold two beliefs is not a draw of its seed (docs/turnaround.md, H17);
    # every other network starts as without it.
    feature_embed_gain: float | None = None
    # The actor-critic's network ("cleanrl": separate ReLU embeddings, orthogonal init, mean head ×0.01; or
    # "reference": the reference code's tanh embeddings shared by actor and critic, normc init, mean head ×1;
    # see agents/ppo.py ActorCritic). hidden, embed and feature_embed_gain apply to both.
    network: str = "cleanrl"
    init_log_std: float = 0.0
    norm_obs: bool = True
    norm_reward: bool = True
    reward_clip: float = 10.0


@dataclasses.dataclass(frozen=True)
class VAEConfig:
    """variBAD's VAE (Zintgraf et al. 2020, appendix B.2), also the task-supervised belief's encoder."""

    latent_dim: int = 5
    gru_hidden: int = 128
    action_embed: int = 16
    state_embed: int = 32
    reward_embed: int = 16
    decoder_hidden: tuple[int, ...] = (64, 32)
    decode_state: bool = False
    kl_weight: float = 1.0
    lr: float = 1e-3
    buffer_trajectories: int = 1000
    batch_trajectories: int = 10
    updates_per_iteration: int = 1
    subsample_elbos: int = 50  # ELBO timesteps per trajectory per update (0: all)
    subsample_decodes: int = 50  # decoded timesteps per ELBO term (0: all)


@dataclasses.dataclass(frozen=True)
class RecurrentConfig:
    """RL²: a GRU over (state, previous action, previous reward, done) inside the policy."""

    hidden: int = 128
    state_embed: int = 32
    action_embed: int = 16
    reward_embed: int = 16


@dataclasses.dataclass(frozen=True)
class BonusConfig:
    """One exploration bonus. `kind`: rnd | ensemble_rnd | vae_error. `input`: state | belief | hyperstate."""

    kind: str = "rnd"
    input: str = "hyperstate"
    # The state part of the bonus input. "task": the position keys the task declares (`x_displacement`
    # for the cheetahs, `position` for the point robot and quadruped: the reference's RND sees only the
    # cheetah's x-position); None: every state key; or a tuple of observation keys.
    state_keys: tuple[str, ...] | str | None = "task"
    weight: float = 10.0  # λ in eq. (4)
    hidden: tuple[int, ...] = (256, 256)
    out_dim: int = 128
    part_embed: int = 64  # the prior embeds each input part (state, belief) separately first
    prior_scale: float = 10.0
    lr: float = 1e-4
    batch_size: int = 128
    buffer_size: int = 10_000
    updates_per_iteration: int = 1
    ensemble_size: int = 1  # B in eq. (8)-(9)
    beta: float = 1.0
    aleatoric: float = 0.0  # σ_A² in eq. (8)-(9)
    # RND inputs: "running" divides by a running std (after the mean) and clips at ±5; "none" feeds them raw
    # (metres, belief values), as the reference code does (rnd_norm_inputs=False).
    input_norm: str = "running"
    # How `prior_scale` enters the fixed prior network: "output" multiplies its output; "weights" multiplies
    # every weight and bias, as the reference code does (rnd_init_weight_scale).
    prior_scaling: str = "output"
    clip: float | None = None  # clip this bonus to ±clip after normalisation, before weighting (reference oracle: 10)
    # What the predictor trains on. "rollout": minibatches from a ring buffer of the last `buffer_size` inputs,
    # beliefs as collected. "replay": minibatches drawn from the whole trajectories the belief stores for its
    # own training (⌊√batch_size⌋ steps of each of batch_size // ⌊√batch_size⌋ trajectories), the belief
    # recomputed by its current model, as the reference code trains the RND of its variBAD agents (whose
    # latent drifts as the encoder learns); needs a belief with `replay_features` (varibad, task_supervised).
    train_on: str = "rollout"
    # Linear annealing of this bonus's weight to 0 at this fraction of training (1.0: at the end, the reference's
    # schedule; 0.5: twice as fast, e.g. a state bonus annealed before the hyper-state one); None: constant,
    # unless AgentConfig.anneal_bonus anneals every bonus over the whole run.
    anneal_until: float | None = None
    # Fields of a registered bonus of your own (agents.register_bonus), validated by that component.
    params: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        _check_choice("input_norm", self.input_norm, ("running", "none"))
        _check_choice("prior_scaling", self.prior_scaling, ("output", "weights"))
        _check_choice("train_on", self.train_on, ("rollout", "replay"))
        if self.clip is not None and not self.clip > 0:
            raise ValueError(f"clip must be positive or null, got {self.clip}")
        if self.anneal_until is not None and not self.anneal_until > 0:
            raise ValueError(f"anneal_until must be a positive fraction of training or null, got {self.anneal_until}")


@dataclasses.dataclass(frozen=True)
class AgentConfig:
    """A whole agent: PPO + one belief + weighted bonuses."""

    # A registered belief component: none | recurrent | oracle | varibad | task_supervised | task_aware, or
    # one of your own (agents.register_belief), which gets `belief_params`.
    belief: str = "none"
    belief_params: dict = dataclasses.field(default_factory=dict)
    ppo: PPOConfig = PPOConfig()
    vae: VAEConfig = VAEConfig()
    recurrent: RecurrentConfig = RecurrentConfig()
    bonuses: tuple[BonusConfig, ...] = ()
    anneal_bonus: bool = False  # multiply every bonus by 1 - frames / total_frames
    # The frames over which bonus annealing (`anneal_bonus`, `bonuses.i.anneal_until`) counts its progress;
    # None: the run's budget. With `ppo.lr_anneal_frames` set alike, a shorter run trains exactly as the first
    # frames of a run of this budget, annealed presets (the `_icml` ones) included.
    bonus_anneal_frames: int | None = None
    state_keys: tuple[str, ...] | None = None  # None: every non-privileged observation key
    # Seed of the networks' initial weights (belief, actor-critic, bonus networks); None: the run's seed. The
    # run's seed still draws the tasks, the action noise and the minibatches, so a seed's outcome can be split
    # into its initialisation and its experience (docs/turnaround.md, runs 32-37).
    init_seed: int | None = None
    # The bonuses' networks (RND priors and predictors) exactly as a run with init_seed = bonus_init_seed would
    # start them, the belief's and actor-critic's from init_seed; None: all from init_seed.
    bonus_init_seed: int | None = None
    torch_threads: int = 1
    physics_threads: int = 0  # 0: one per CPU
    checkpoint_every: int = 10  # iterations (0: only at the end and when the caller asks, see Agent.train)

    def __post_init__(self) -> None:
        if self.bonus_anneal_frames is not None and self.bonus_anneal_frames <= 0:
            raise ValueError(f"bonus_anneal_frames must be positive or null, got {self.bonus_anneal_frames}")

    @property
    def value_heads(self) -> int:
        """Critic outputs: 1 (one return), or 2 (extrinsic and intrinsic returns: `ppo.intrinsic_gamma` set
        and at least one bonus)."""
        return 2 if self.ppo.intrinsic_gamma is not None and self.bonuses else 1


def to_dict(config: Any) -> Any:
    """A JSON-ready dict of a config (tuples become lists)."""
    return dataclasses.asdict(config)


def from_dict(cls: type, data: dict) -> Any:
    """Rebuilds a config from `to_dict` output (lists become tuples)."""
    return apply_overrides(cls(), data) if cls is not AgentConfig else _agent_from_dict(data)


def _agent_from_dict(data: dict) -> AgentConfig:
    data = dict(data)
    bonuses = tuple(apply_overrides(BonusConfig(), b, f"bonuses.{i}.") for i, b in enumerate(data.pop("bonuses", ())))
    return apply_overrides(dataclasses.replace(AgentConfig(), bonuses=bonuses), data)


def _coerce(value: Any, current: Any, path: str) -> Any:
    if path.endswith("state_keys"):  # a tuple of keys, None, or (bonuses) the sentinel "task"
        if isinstance(value, (list, tuple)):
            return tuple(value)
        if value is None or (value == "task" and "bonuses" in path):
            return value
        allowed = 'a list of observation keys, "task" or null' if "bonuses" in path else "a list of keys or null"
        raise ValueError(f"{path} must be {allowed}, got {value!r}")
    if isinstance(current, tuple) or (current is None and isinstance(value, list)):
        return tuple(value) if isinstance(value, (list, tuple)) else value
    if isinstance(current, bool):
        if not isinstance(value, bool):
            raise ValueError(f"{path} must be true or false, got {value!r}")
        return value
    if isinstance(current, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if current is not None and not isinstance(value, type(current)) and value is not None:
        raise ValueError(f"{path} must be {type(current).__name__}, got {value!r}")
    return value


def apply_overrides(config: Any, overrides: dict[str, Any], prefix: str = "") -> Any:
    """Returns `config` with overrides applied (dotted keys or nested dicts)."""
    nested: dict[str, Any] = {}
    for key, value in overrides.items():
        head, _, rest = key.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = value
        elif isinstance(value, dict):
            nested.setdefault(head, {}).update(value)
        else:
            nested.setdefault(head, {})[""] = value
    fields = {f.name: f for f in dataclasses.fields(config)}
    changes = {}
    for name, sub in nested.items():
        path = f"{prefix}{name}"
        if name not in fields:
            close = difflib.get_close_matches(name, fields, n=3)
            hint = f" (did you mean {', '.join(prefix + c for c in close)}?)" if close else ""
            raise ValueError(f"unknown config field {path!r}{hint}; valid: {', '.join(prefix + f for f in fields)}")
        current = getattr(config, name)
        direct = sub.pop("", dataclasses.MISSING)
        if isinstance(current, dict):  # a component's own parameters: replaced as a whole, or per key
            if direct is not dataclasses.MISSING and not isinstance(direct, dict):
                raise ValueError(f"{path} must be a mapping, got {direct!r}")
            changes[name] = {**(current if direct is dataclasses.MISSING else direct), **sub}
        elif dataclasses.is_dataclass(current):
            if direct is not dataclasses.MISSING:
                raise ValueError(f"{path} is a section; set its fields, e.g. {path}.{next(iter(fields))}")
            changes[name] = apply_overrides(current, sub, prefix=f"{path}.")
        elif name == "bonuses":
            changes[name] = _override_bonuses(current, direct, sub, path)
        else:
            if sub:
                raise ValueError(f"{path} has no fields ({', '.join(path + '.' + k for k in sub)})")
            changes[name] = _coerce(direct, current, path)
    return dataclasses.replace(config, **changes)


def _override_bonuses(current: tuple, direct: Any, sub: dict, path: str) -> tuple:
    bonuses = list(current)
    if direct is not dataclasses.MISSING:
        bonuses = [
            b if isinstance(b, BonusConfig) else apply_overrides(BonusConfig(), b, f"{path}.{i}.")
            for i, b in enumerate(direct)
        ]
    per_index: dict[int, dict] = {}
    for key, value in sub.items():
        index, _, field = key.partition(".")
        if not index.isdigit() or int(index) >= len(bonuses):
            raise ValueError(f"{path}.{key}: bonus index must be 0..{len(bonuses) - 1}")
        per_index.setdefault(int(index), {})[field] = value
    for i, fields in per_index.items():
        bonuses[i] = apply_overrides(bonuses[i], fields, prefix=f"{path}.{i}.")
    return tuple(bonuses)
