"""Agent configuration: frozen dataclasses whose defaults are the validated agents' settings.

Overrides use dotted names (`"ppo.lr"`, `"vae.latent_dim"`, `"bonuses.0.weight"`) or nested dicts;
an unknown name is a `ValueError` that lists the valid ones.
"""

from __future__ import annotations

import dataclasses
import difflib
from typing import Any, Literal


def _check_choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ValueError(f"{name} must be one of {', '.join(map(repr, choices))}; got {value!r}")


def _check_positive(section: str, config: Any, *names: str, allow_zero: bool = False) -> None:
    """ValueError naming the field if a numeric field is not positive (or negative, with allow_zero)."""
    for name in names:
        value = getattr(config, name)
        if value is not None and (value < 0 if allow_zero else value <= 0):
            bound = ">= 0" if allow_zero else "positive"
            raise ValueError(f"{section}{name} must be {bound}, got {value!r}")


def _check_fraction(section: str, config: Any, *names: str, closed: bool = True) -> None:
    for name in names:
        value = getattr(config, name)
        if value is not None and not (0.0 <= value <= 1.0 if closed else 0.0 < value < 1.0):
            interval = "[0, 1]" if closed else "(0, 1)"
            raise ValueError(f"{section}{name} must be in {interval}, got {value!r}")


@dataclasses.dataclass(frozen=True)
class PPOConfig:
    """PPO hyperparameters. The defaults are the validated agents' (docs/agents.md, "Presets"): the reference
    code's PPO on sparse cheetah-dir, with the learning rate on its 5e7-frame schedule and its network."""

    num_envs: int = 16
    """Environments stepped in parallel (one batched simulator)."""
    rollout_length: int = 200
    """Control steps per environment per update; a multiple of the BAMDP length."""
    lr: float = 7e-4
    """Adam's learning rate for the actor-critic (and the belief's policy-side parameters)."""
    anneal_lr: bool = True
    """Whether the learning rate falls linearly to 0."""
    lr_anneal_frames: int | None = 50_000_000
    """Frames over which the rate falls to 0, whatever the budget, so a shorter run trains as the first frames of
    a longer one and a run can be extended exactly; None: over the run's budget."""
    gamma: float = 0.97
    """Discount of the (extrinsic plus weighted intrinsic) return."""
    gae_lambda: float = 0.9
    """GAE's λ."""
    clip: float = 0.1
    """PPO's ratio clip, also the value clip of `value_loss="clipped_huber"`."""
    epochs: int = 2
    """Passes over each rollout."""
    minibatches: int = 4
    """Minibatches per pass."""
    entropy_coef: float = 1e-4
    """Weight of the policy's entropy in the loss."""
    value_coef: float = 0.5
    """Weight of the value loss."""
    value_loss: Literal["mse", "clipped_huber"] = "clipped_huber"
    """"mse": 0.5 (V - R)²; "clipped_huber": 0.5 max(huber(V, R), huber(V_old + clip(V - V_old, ±clip), R))."""
    minibatch_unit: Literal["envs", "transitions"] = "transitions"
    """Minibatches of transitions shuffled across envs and steps, or of whole env sequences ("envs": needed by a
    belief trained through time in the policy's loss, such as RL²'s GRU)."""
    advantage_norm: Literal["minibatch", "batch"] = "batch"
    """Advantages standardised once over the whole rollout ("batch") or per minibatch."""
    sampled_action_cost: float = 0.05
    """Adds coef · (|a|² - |clip(a)|²) of the sampled action a to the training reward: the task charges its
    control cost on the clipped action, the reference's environments on the sampled one (0.05 is the cheetah's
    control-cost weight). Charged on every task, control cost or not, so that a preset is one agent across
    the catalogue: it only touches the part of a sample beyond the action bounds, which no task rewards;
    deployment is unaffected."""
    intrinsic_gamma: float | None = None
    """None: the weighted bonuses join the extrinsic reward and one critic learns the sum. A discount: a second
    critic head learns the intrinsic return alone, discounted by it (RND's two value heads)."""
    max_grad_norm: float = 0.5
    """Gradient-norm clip of each update."""
    hidden: tuple[int, ...] = (128, 128)
    """Hidden layers of actor and critic."""
    embed: int = 32
    """State and belief features are each embedded to this size first (0: no embedding)."""
    feature_embed_gain: float | None = None
    """Initial weights of the belief-features embedding: None, PyTorch's default; a gain g: orthogonal × g and
    zero biases, so how far apart the first policy holds two beliefs is not a draw of its seed."""
    network: Literal["cleanrl", "reference"] = "reference"
    """"reference": tanh embeddings shared by actor and critic, normc init, mean head × 1 (the first policy acts at
    full scale, differently per belief); "cleanrl": separate ReLU embeddings, orthogonal init, mean head × 0.01."""
    init_log_std: float = 0.0
    """Initial log standard deviation of the Gaussian policy."""
    norm_obs: bool = True
    """Normalise observations by running mean and std."""
    norm_reward: bool = True
    """Divide rewards by the running std of the discounted return."""
    reward_clip: float = 10.0
    """Clip of the normalised reward."""

    def __post_init__(self) -> None:
        for name, choices in (
            ("value_loss", ("mse", "clipped_huber")),
            ("minibatch_unit", ("envs", "transitions")),
            ("advantage_norm", ("minibatch", "batch")),
            ("network", ("cleanrl", "reference")),
        ):
            _check_choice(f"ppo.{name}", getattr(self, name), choices)
        _check_positive("ppo.", self, "num_envs", "rollout_length", "lr", "epochs", "minibatches", "max_grad_norm")
        _check_positive("ppo.", self, "lr_anneal_frames", "feature_embed_gain", "reward_clip")
        _check_positive("ppo.", self, "entropy_coef", "value_coef", "sampled_action_cost", "clip", allow_zero=True)
        _check_positive("ppo.", self, "embed", allow_zero=True)
        _check_fraction("ppo.", self, "gamma", "gae_lambda")
        _check_fraction("ppo.", self, "intrinsic_gamma", closed=False)
        if any(h <= 0 for h in self.hidden):
            raise ValueError(f"ppo.hidden sizes must be positive, got {self.hidden}")


@dataclasses.dataclass(frozen=True)
class VAEConfig:
    """variBAD's VAE (Zintgraf et al. 2020, appendix B.2), also the task-supervised belief's encoder."""

    latent_dim: int = 5
    """Size of the latent task variable m (the belief is its mean and log-variance)."""
    gru_hidden: int = 128
    """Hidden size of the encoder's GRU."""
    action_embed: int = 16
    """Encoder's action embedding."""
    state_embed: int = 32
    """Encoder's state embedding."""
    reward_embed: int = 16
    """Encoder's reward embedding."""
    decoder_hidden: tuple[int, ...] = (64, 32)
    """Hidden layers of the reward (and state) decoder."""
    decode_state: bool = False
    """Also decode the next state (variBAD's optional state decoder)."""
    kl_weight: float = 1.0
    """Weight of the KL term of the ELBO."""
    lr: float = 1e-3
    """Adam's learning rate for the VAE."""
    buffer_trajectories: int = 1000
    """Trajectories kept for the VAE's training."""
    batch_trajectories: int = 10
    """Trajectories per VAE update."""
    updates_per_iteration: int = 1
    """VAE updates per PPO iteration."""
    subsample_elbos: int = 50
    """ELBO timesteps per trajectory per update (0: all)."""
    subsample_decodes: int = 50
    """Decoded timesteps per ELBO term (0: all)."""

    def __post_init__(self) -> None:
        _check_positive("vae.", self, "latent_dim", "gru_hidden", "lr", "buffer_trajectories", "batch_trajectories")
        _check_positive("vae.", self, "updates_per_iteration", "kl_weight", "subsample_elbos", allow_zero=True)
        _check_positive("vae.", self, "subsample_decodes", allow_zero=True)


@dataclasses.dataclass(frozen=True)
class RecurrentConfig:
    """RL²: a GRU over (state, previous action, previous reward, done) inside the policy."""

    hidden: int = 128
    """Hidden size of the GRU."""
    state_embed: int = 32
    """State embedding before the GRU."""
    action_embed: int = 16
    """Previous-action embedding."""
    reward_embed: int = 16
    """Previous-reward embedding."""

    def __post_init__(self) -> None:
        _check_positive("recurrent.", self, "hidden", "state_embed", "action_embed", "reward_embed")


@dataclasses.dataclass(frozen=True)
class BonusConfig:
    """One exploration bonus. `kind`: rnd | ensemble_rnd | vae_error. `input`: state | belief | hyperstate."""

    kind: str = "rnd"
    """A registered bonus component: rnd | ensemble_rnd | vae_error, or your own (agents.register_bonus)."""
    input: str = "hyperstate"
    """What the bonus sees: "state", "belief" or "hyperstate" (both)."""
    state_keys: tuple[str, ...] | str | None = "task"
    """The state part of the input: "task", the position keys the task declares (the cheetah's x-position); None:
    every state key; or a tuple of observation keys."""
    weight: float = 10.0
    """λ in eq. (4)."""
    hidden: tuple[int, ...] = (256, 256)
    """Hidden layers of RND's prior and predictor."""
    out_dim: int = 128
    """Output size of RND's networks."""
    part_embed: int = 64
    """The prior embeds each input part (state, belief) separately to this size first."""
    prior_scale: float = 10.0
    """Scale of the fixed prior network (see `prior_scaling`)."""
    lr: float = 1e-4
    """Adam's learning rate for the predictor."""
    batch_size: int = 128
    """Inputs per predictor update."""
    buffer_size: int = 100_000
    """Ring buffer of recent inputs the predictor trains on (the reference: 10,000)."""
    updates_per_iteration: int = 4
    """Predictor updates per PPO iteration (the reference: 1, with which the bonus stays a fixed random function
    of the input on cheetah_dir_sparse; see docs/agents.md)."""
    ensemble_size: int = 1
    """B in eq. (8)-(9)."""
    beta: float = 1.0
    """β in eq. (8)-(9)."""
    aleatoric: float = 0.0
    """σ_A² in eq. (8)-(9)."""
    input_norm: Literal["running", "none"] = "running"
    """"running": inputs minus a running mean, divided by a running std, clipped at ±5; "none": raw (metres,
    belief values), as the reference code."""
    prior_scaling: Literal["output", "weights"] = "output"
    """How `prior_scale` enters the prior network: it multiplies the output, or every weight and bias (the
    reference code)."""
    clip: float | None = None
    """Clip this bonus to ±clip after normalisation, before weighting (the reference's oracle: 10)."""
    train_on: Literal["rollout", "replay"] = "rollout"
    """"rollout": minibatches from the ring buffer, beliefs as collected; "replay": from the belief's stored
    trajectories with beliefs recomputed by its current model (the reference's variBAD RND; needs a belief with
    `replay_features`)."""
    anneal_until: float | None = None
    """Anneal this bonus's weight linearly to 0 at this fraction of training; None: constant, unless
    AgentConfig.anneal_bonus anneals every bonus over the whole run."""
    params: dict = dataclasses.field(default_factory=dict)
    """Fields of a registered bonus of your own, validated by that component."""

    def __post_init__(self) -> None:
        _check_choice("input_norm", self.input_norm, ("running", "none"))
        _check_choice("prior_scaling", self.prior_scaling, ("output", "weights"))
        _check_choice("train_on", self.train_on, ("rollout", "replay"))
        if self.clip is not None and not self.clip > 0:
            raise ValueError(f"clip must be positive or null, got {self.clip}")
        if self.anneal_until is not None and not self.anneal_until > 0:
            raise ValueError(f"anneal_until must be a positive fraction of training or null, got {self.anneal_until}")
        _check_positive("", self, "out_dim", "prior_scale", "lr", "batch_size", "buffer_size", "ensemble_size")
        _check_positive("", self, "weight", "updates_per_iteration", "beta", "aleatoric", "part_embed", allow_zero=True)


@dataclasses.dataclass(frozen=True)
class AgentConfig:
    """A whole agent: PPO + one belief + weighted bonuses."""

    belief: str = "none"
    """A registered belief: none | recurrent | oracle | varibad | task_supervised | task_aware, or your own."""
    belief_params: dict = dataclasses.field(default_factory=dict)
    """Fields of a registered belief of your own (agents.register_belief)."""
    ppo: PPOConfig = PPOConfig()
    """PPO and the actor-critic."""
    vae: VAEConfig = VAEConfig()
    """The VAE of the varibad and task_supervised beliefs."""
    recurrent: RecurrentConfig = RecurrentConfig()
    """The GRU of the recurrent (RL²) belief."""
    bonuses: tuple[BonusConfig, ...] = ()
    """The exploration bonuses, each weighted into the reward by eq. (4)."""
    anneal_bonus: bool = False
    """Multiply every bonus by 1 - frames / total frames."""
    bonus_anneal_frames: int | None = None
    """The frames over which bonus annealing counts its progress; None: the run's budget."""
    state_keys: tuple[str, ...] | None = None
    """Observation keys the policy sees; None: every non-privileged key."""
    init_seed: int | None = None
    """Seed of the networks' initial weights; None: the run's seed, which always draws tasks, noise and
    minibatches, so a seed's outcome can be split into its initialisation and its experience."""
    bonus_init_seed: int | None = None
    """Seed of the bonus networks' initial weights alone; None: as the other networks."""
    torch_threads: int = 1
    """Runtime: torch's intra-op threads."""
    physics_threads: int = 0
    """Runtime: physics threads of the batched simulator (0: $HYPERSTATE_PHYSICS_THREADS, else one per CPU)."""
    checkpoint_every: int = 10
    """Runtime: iterations between checkpoints (0: only at the end and when the caller asks)."""

    def __post_init__(self) -> None:
        if self.bonus_anneal_frames is not None and self.bonus_anneal_frames <= 0:
            raise ValueError(f"bonus_anneal_frames must be positive or null, got {self.bonus_anneal_frames}")
        _check_positive("", self, "torch_threads")
        _check_positive("", self, "physics_threads", "checkpoint_every", allow_zero=True)

    @property
    def value_heads(self) -> int:
        """Critic outputs: 1 (one return), or 2 (extrinsic and intrinsic returns: `ppo.intrinsic_gamma` set
        and at least one bonus)."""
        return 2 if self.ppo.intrinsic_gamma is not None and self.bonuses else 1


# Settings of how a run uses the machine, not of the agent: results do not depend on them.
RUNTIME_FIELDS = ("torch_threads", "physics_threads", "checkpoint_every")


def agent_settings(config: AgentConfig | dict) -> dict:
    """The agent's settings as JSON-ready data, without the runtime fields: what two runs must share to be
    runs of one agent (a record's `config` is accepted too)."""
    data = to_dict(config) if dataclasses.is_dataclass(config) else dict(config)
    return {k: v for k, v in data.items() if k not in RUNTIME_FIELDS}


def budget_dependence(config: AgentConfig) -> str | None:
    """Why training would change with the budget (a schedule that follows it), or None: then a run of F frames
    trains exactly as the first F frames of any longer run, and a finished run can be extended."""
    if config.ppo.anneal_lr and config.ppo.lr_anneal_frames is None:
        return "ppo.lr_anneal_frames is null, so the learning rate anneals over the budget"
    annealed = config.anneal_bonus or any(b.anneal_until is not None for b in config.bonuses)
    if annealed and config.bonus_anneal_frames is None:
        return "bonus_anneal_frames is null, so the bonuses anneal over the budget"
    return None


def check_budget(config: AgentConfig, frames: int) -> None:
    """ValueError in one line if `frames` outlasts the fixed learning-rate schedule (the rate would be 0)."""
    p = config.ppo
    if p.anneal_lr and p.lr_anneal_frames is not None and frames > p.lr_anneal_frames:
        raise ValueError(
            f"a budget of {frames:,} frames outlasts ppo.lr_anneal_frames = {p.lr_anneal_frames:,} (the learning "
            f"rate would be 0 after it); set ppo.lr_anneal_frames to at least the budget"
        )


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
