"""Exploration bonus components: random network distillation (RND) on a chosen input, its ensemble
version with the uncertainty of eq. (8)-(9), and variBAD's reconstruction error.

Each bonus sees a `BonusInput` for a whole rollout at once (never per env per step) and returns one
bonus per transition; its weight, normalisation and annealing live in the agent (eq. 4).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Protocol

import numpy as np
import torch
from torch import nn

from hyperstate.agents.config import BonusConfig
from hyperstate.agents.networks import mlp
from hyperstate.agents.normalization import RunningMeanStd
from hyperstate.registry import Registry, no_params


@dataclasses.dataclass
class BonusInput:
    """Flattened transitions (M = T * N rows) of one rollout."""

    state: torch.Tensor  # raw s_t
    action: torch.Tensor
    reward: torch.Tensor  # (M, 1) raw extrinsic reward
    next_state: torch.Tensor  # raw s_{t+1} (the final observation where the BAMDP episode ended)
    features: torch.Tensor  # belief features b_t
    next_features: torch.Tensor  # belief features b_{t+1}, after observing s_{t+1}
    # `replay(n)`: about n transitions drawn from the whole trajectories the belief stores, with the belief
    # recomputed by its current model (a `BonusInput` without `replay`), or None while none is stored; None
    # where the belief stores none. For bonuses that train on replayed experience (`BonusConfig.train_on`).
    replay: Callable[[int], BonusInput | None] | None = None


class Bonus(Protocol):
    """An exploration bonus (register your own with `agents.register_bonus`)."""

    name: str

    @classmethod
    def build(
        cls, config: BonusConfig, *, state_columns: list[int], belief, generator: torch.Generator, name: str
    ) -> Bonus:
        """The component for one `BonusConfig` of an agent (see `register_bonus`)."""

    def reward(self, batch: BonusInput) -> torch.Tensor:
        """(M,) bonus per transition; no gradients."""

    def update(self, batch: BonusInput) -> dict[str, float]:
        """Trains on the rollout's inputs; returns logged losses."""

    # Optional: `value(batch) -> (M,)`, the bonus at these inputs learning nothing from them (no statistics
    # updated), for diagnostics (evaluation/diagnostics.py); `deployable(state) -> dict`, the part of
    # `state_dict()` a saved agent carries (without it, all of it).

    def state_dict(self) -> dict: ...

    def load_state_dict(self, state: dict) -> None: ...


class InputSelector:
    """Picks the bonus input from a transition: chosen state columns of s_{t+1}, b_{t+1}, or both."""

    KINDS = ("state", "belief", "hyperstate")

    def __init__(self, kind: str, state_columns: list[int], belief_dim: int):
        if kind not in self.KINDS:
            raise ValueError(f"unknown bonus input {kind!r}; inputs: {', '.join(self.KINDS)}")
        if kind != "state" and belief_dim == 0:
            raise ValueError(f"a {kind} bonus needs a belief with features (not belief 'none')")
        self.kind = kind
        self.state_columns = torch.as_tensor(state_columns, dtype=torch.long)
        self.parts = []  # sizes of the input parts, in order
        if kind in ("state", "hyperstate"):
            self.parts.append(len(state_columns))
        if kind in ("belief", "hyperstate"):
            self.parts.append(belief_dim)

    @property
    def dim(self) -> int:
        return sum(self.parts)

    def __call__(self, batch: BonusInput) -> torch.Tensor:
        parts = []
        if self.kind in ("state", "hyperstate"):
            parts.append(batch.next_state[:, self.state_columns])
        if self.kind in ("belief", "hyperstate"):
            parts.append(batch.next_features)
        return torch.cat(parts, dim=-1)


class RunningInputNorm:
    """RND's input normalisation: by the running mean and std of every input seen, clipped to ±5."""

    def __init__(self, stats: RunningMeanStd):
        self.stats = stats

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        return self.stats.normalize(x, clip=5.0).float()


class RawInputs:
    """Inputs as they are (`input_norm="none"`)."""

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        return x.float()


class PriorNetwork(nn.Module):
    """RND's fixed random network f: each input part embedded separately, then an MLP.

    `prior_scaling="output"` multiplies its output by `prior_scale`. `"weights"` multiplies every weight
    and bias instead, as the reference code does: with four layers that scales large outputs by up to
    prior_scale⁴ (and changes the function's shape, since biases grow with the weights), leaving the
    predictor chasing targets of order 10⁴ at scale 10.
    """

    def __init__(self, parts: list[int], config: BonusConfig):
        super().__init__()
        self.parts = parts
        self.embeds = nn.ModuleList(nn.Linear(p, config.part_embed) for p in parts)
        self.body = mlp([config.part_embed * len(parts), *config.hidden, config.out_dim], nn.ReLU)
        self.scale = config.prior_scale if config.prior_scaling == "output" else 1.0
        if config.prior_scaling == "weights":
            with torch.no_grad():
                for parameter in self.parameters():
                    parameter.mul_(config.prior_scale)
        self.requires_grad_(False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        chunks = torch.split(x, self.parts, dim=-1)
        embedded = torch.relu(torch.cat([e(c) for e, c in zip(self.embeds, chunks, strict=True)], dim=-1))
        return self.scale * self.body(embedded)


_BONUSES: Registry[type] = Registry("bonus kind", "kinds")


def register_bonus(kind: str) -> Callable[[type], type]:
    """Class decorator: makes a bonus component selectable as `BonusConfig(kind=kind)`.

    The class follows the `Bonus` protocol (`reward`, `update`, `state_dict`, `load_state_dict`; optionally
    `value` for diagnostics) and has a classmethod `build(config, *, state_columns, belief, generator, name)`
    returning an instance: `config` is its `BonusConfig` (own settings in `config.params`, which the
    component validates), `state_columns` the state-vector columns of the config's `state_keys`, `belief`
    the agent's belief component, `generator` the agent's seeded torch generator, `name` its log name.
    """
    _BONUSES.check_free(kind)

    def decorator(cls: type) -> type:
        _BONUSES.check_free(kind)
        missing = [m for m in ("build", "reward", "update", "state_dict", "load_state_dict") if not hasattr(cls, m)]
        if missing:
            lacks = ", ".join(missing)
            raise TypeError(f"bonus {kind!r} ({cls.__qualname__}) lacks {lacks} (see agents.bonuses.Bonus)")
        return _BONUSES.add(kind, cls, owner=cls.__module__)

    return decorator


@register_bonus("rnd")
@register_bonus("ensemble_rnd")
class EnsembleRND:
    """B prior/predictor pairs; bonus σ² = max(0, mean_i e_i + β var_i e_i − σ_A²), eq. (8)-(9).

    e_i is the mean squared difference of predictor i and prior i over their outputs. With B = 1 this is
    plain RND (Burda et al. 2019): the bonus ‖f(x) − g(x)‖² (averaged over outputs).
    """

    @classmethod
    def build(cls, config: BonusConfig, *, state_columns, belief, generator, name) -> EnsembleRND:
        no_params(f"the {config.kind!r} bonus", config.params)
        if config.kind == "rnd" and config.ensemble_size != 1:
            raise ValueError("kind 'rnd' has ensemble_size 1; use kind 'ensemble_rnd' for an ensemble")
        replays = belief.trainable and callable(getattr(belief, "replay_features", None))
        if config.train_on == "replay" and not replays:
            raise ValueError(
                f"train_on 'replay' needs a belief that stores trajectories and recomputes its features "
                f"(replay_features: varibad, task_supervised); {type(belief).__name__} does not"
            )
        return cls(InputSelector(config.input, state_columns, belief.feature_dim), config, generator, name)

    def __init__(self, selector: InputSelector, config: BonusConfig, generator: torch.Generator, name: str):
        self.name = name
        self.config = config
        self.selector = selector
        self.generator = generator
        b = config.ensemble_size
        if b < 1:
            raise ValueError(f"ensemble_size must be >= 1, got {b}")
        self.priors = nn.ModuleList(PriorNetwork(selector.parts, config) for _ in range(b))
        self.predictors = nn.ModuleList(mlp([selector.dim, *config.hidden, config.out_dim], nn.ReLU) for _ in range(b))
        self.optimizer = torch.optim.Adam(self.predictors.parameters(), lr=config.lr)
        self.input_stats = RunningMeanStd((selector.dim,))
        # Trained on replayed trajectories, the predictor keeps no inputs of its own.
        replay = config.train_on == "replay"
        kept = 0 if replay else config.buffer_size
        self.buffer = np.zeros((kept, selector.dim), np.float32)
        self.buffer_len = 0
        self.buffer_pos = 0
        # Strategies chosen once: how inputs reach the networks, where the predictor's minibatches come from.
        self.normalize = RawInputs() if config.input_norm == "none" else RunningInputNorm(self.input_stats)
        self._training_minibatches = self._replayed_minibatches if replay else self._buffered_minibatches

    def errors(self, x: torch.Tensor) -> torch.Tensor:
        """(B, M) squared prediction errors of each ensemble member on normalised inputs x."""
        return torch.stack([(g(x) - f(x)).pow(2).mean(-1) for f, g in zip(self.priors, self.predictors, strict=True)])

    @staticmethod
    def uncertainty(errors: torch.Tensor, beta: float, aleatoric: float) -> torch.Tensor:
        """Eq. (8)-(9) from (B, M) errors: max(0, mean + β·var − σ_A²); var is 0 for B = 1."""
        mean = errors.mean(0)
        var = errors.var(0, unbiased=False) if errors.shape[0] > 1 else torch.zeros_like(mean)
        return torch.clamp(mean + beta * var - aleatoric, min=0.0)

    def reward(self, batch: BonusInput) -> torch.Tensor:
        x = self.selector(batch)
        # Inputs are normalised with statistics that include this rollout (as RND does).
        self.input_stats.update(x.numpy())
        with torch.no_grad():
            return self.uncertainty(self.errors(self.normalize(x)), self.config.beta, self.config.aleatoric)

    def value(self, batch: BonusInput) -> torch.Tensor:
        """The bonus at these inputs under the current statistics, learning nothing from them."""
        with torch.no_grad():
            x = self.normalize(self.selector(batch))
            return self.uncertainty(self.errors(x), self.config.beta, self.config.aleatoric)

    def update(self, batch: BonusInput) -> dict[str, float]:
        return self._fit(self._training_minibatches(batch))

    def _buffered_minibatches(self, batch: BonusInput) -> list[torch.Tensor]:
        """The rollout's inputs into the ring buffer; `updates_per_iteration` minibatches drawn from it."""
        x = self.selector(batch).numpy().astype(np.float32)
        n = len(x)
        idx = (self.buffer_pos + np.arange(n)) % self.config.buffer_size
        self.buffer[idx[-self.config.buffer_size :]] = x[-self.config.buffer_size :]
        self.buffer_pos = int((self.buffer_pos + n) % self.config.buffer_size)
        self.buffer_len = min(self.buffer_len + n, self.config.buffer_size)
        minibatches = []
        for _ in range(self.config.updates_per_iteration):
            rows = torch.randint(self.buffer_len, (self.config.batch_size,), generator=self.generator)
            minibatches.append(torch.from_numpy(self.buffer[rows.numpy()]))
        return minibatches

    def _replayed_minibatches(self, batch: BonusInput) -> list[torch.Tensor]:
        """`updates_per_iteration` minibatches of replayed trajectories (`train_on="replay"`)."""
        return [self._replayed(batch) for _ in range(self.config.updates_per_iteration)]

    def _replayed(self, batch: BonusInput) -> torch.Tensor:
        """One minibatch of replayed inputs; until the belief has stored a whole trajectory, rows of `batch`."""
        replayed = batch.replay(self.config.batch_size) if batch.replay is not None else None
        if replayed is not None:
            return self.selector(replayed).float()
        x = self.selector(batch)
        return x[torch.randint(len(x), (self.config.batch_size,), generator=self.generator)].float()

    def _fit(self, minibatches: list[torch.Tensor]) -> dict[str, float]:
        """One predictor step per minibatch of raw inputs."""
        losses = []
        for x in minibatches:
            loss = self.errors(self.normalize(x)).mean()
            self.optimizer.zero_grad()
            loss.backward()
            self.optimizer.step()
            losses.append(loss.item())
        return {f"bonus/{self.name}/predictor_loss": float(np.mean(losses))}

    def state_dict(self) -> dict:
        return {
            "priors": self.priors.state_dict(),
            "predictors": self.predictors.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "input_stats": self.input_stats.state_dict(),
            "buffer": self.buffer[: self.buffer_len].copy(),
            "buffer_pos": self.buffer_pos,
        }

    def load_state_dict(self, state: dict) -> None:
        """Loads a training checkpoint's state, or a deployed agent's (networks and statistics only: no
        input buffer or optimiser, see `deployable`)."""
        self.priors.load_state_dict(state["priors"])
        self.predictors.load_state_dict(state["predictors"])
        self.input_stats.load_state_dict(state["input_stats"])
        if "optimizer" in state:
            self.optimizer.load_state_dict(state["optimizer"])
            self.buffer_len = len(state["buffer"])
            self.buffer[: self.buffer_len] = state["buffer"]
            self.buffer_pos = state["buffer_pos"]

    @staticmethod
    def deployable(state: dict) -> dict:
        """The part of `state_dict()` a deployed agent needs to compute the bonus (not to train it)."""
        return {k: state[k] for k in ("priors", "predictors", "input_stats")}


@register_bonus("vae_error")
class VAEErrorBonus:
    """variBAD's reward-reconstruction error for r_t under a latent sample of the posterior b_t."""

    @classmethod
    def build(cls, config: BonusConfig, *, belief, name, **_) -> VAEErrorBonus:
        no_params(f"the {config.kind!r} bonus", config.params)
        return cls(belief, name)

    def __init__(self, belief, name: str):
        if not getattr(belief, "decodes_reward", False):
            raise ValueError(f"the vae_error bonus needs a belief that decodes rewards (varibad), not {belief.name!r}")
        self.name = name
        self.belief = belief

    def reward(self, batch: BonusInput) -> torch.Tensor:
        return self.belief.reconstruction_error(
            batch.features, batch.state, batch.action, batch.next_state, batch.reward
        )

    def update(self, batch: BonusInput) -> dict[str, float]:
        return {}  # the decoder is trained with the VAE

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, state: dict) -> None:
        pass


def bonus_class(kind: str) -> type:
    """The bonus component registered as `kind`."""
    return _BONUSES.lookup(kind)


def list_bonuses() -> list[str]:
    """Registered bonus kinds, sorted."""
    return _BONUSES.names()


def make_bonus(
    config: BonusConfig, *, state_columns: list[int], belief, generator: torch.Generator, index: int
) -> Bonus:
    """Builds one bonus component from its config (its `kind` names a registered class)."""
    name = f"{index}_{config.kind}_{config.input}"
    return bonus_class(config.kind).build(
        config, state_columns=state_columns, belief=belief, generator=generator, name=name
    )


def unregister_bonus(kind: str) -> None:
    """Removes a registered bonus kind (for tests and interactive sessions)."""
    _BONUSES.remove(kind)
