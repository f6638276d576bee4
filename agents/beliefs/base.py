"""What every belief component shares: the transition and trajectory types, the `Belief` protocol and the
registry that makes a component selectable by name (`AgentConfig(belief=name)`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Protocol

import torch
from torch import nn

from hyperstate import registry
from hyperstate.agents.config import RecurrentConfig, VAEConfig
from hyperstate.agents.rollout import Rollout
from hyperstate.registry import Registry


@dataclasses.dataclass
class Transition:
    """One batched transition, as the belief sees it (all (N, ...) tensors)."""

    action: torch.Tensor
    reward: torch.Tensor  # (N, 1), raw extrinsic reward
    next_state: torch.Tensor  # raw state s_{t+1}
    next_obs: dict[str, torch.Tensor]  # full observation at t+1 (privileged keys included)


@dataclasses.dataclass
class Trajectories:
    """Whole BAMDP episodes for belief training: (B, T+1, S) states, (B, T, A) actions, (B, T, 1) rewards."""

    states: torch.Tensor
    actions: torch.Tensor
    rewards: torch.Tensor
    tasks: torch.Tensor | None  # (B, P) true task parameters, for task-supervised training


class Belief(Protocol):
    """A belief component.

    Capabilities (class attributes, so that a config answers them before anything is built):
    `trainable` — it has its own objective, trained from stored whole trajectories (`train_step`);
    `reads_true_task` — it hands the policy the true task (a reference, not a meta-learner);
    `decodes_reward` — it can reconstruct rewards (`reconstruction_error`, for the VAE-error bonus).
    """

    name: str
    feature_dim: int
    trainable: bool
    reads_true_task: bool
    decodes_reward: bool

    @classmethod
    def build(
        cls, *, state_dim: int, action_dim: int, obs_spec: dict, vae: VAEConfig, recurrent: RecurrentConfig,
        generator: torch.Generator, params: dict,
    ) -> Belief:  # fmt: skip
        """The component for a task with observation spec `obs_spec`; ValueError naming what it lacks."""

    def initial_state(self, n: int, obs: dict[str, torch.Tensor]) -> object:
        """b_0 for a batch of `n` first observations (`obs` holds their privileged keys)."""

    def update(self, state: object, transition: Transition) -> object:
        """b_{t+1} from b_t and the transition (a_t, r_t, s_{t+1})."""

    def reset_where(self, state: object, mask: torch.Tensor, obs: dict[str, torch.Tensor]) -> object:
        """b with the entries where `mask` restarted from the prior (new BAMDP episode)."""

    def features(self, state: object) -> torch.Tensor:
        """(N, feature_dim) features of b_t for the policy and the bonuses."""

    def policy_parameters(self) -> list[nn.Parameter]:
        """Parameters trained by the RL loss (only RL²'s GRU)."""

    def sequence_features(self, rollout: Rollout, env_index: torch.Tensor) -> torch.Tensor:
        """(T, n, F) features of rollout steps for envs `env_index`, with gradients if RL-trained."""

    def train_step(self, trajectories: Trajectories) -> dict[str, float]:
        """One update of the belief's own objective; returns logged losses ({} if untrained)."""

    # Optional, for trainable beliefs: `replay_features(trajectories) -> (B, T+1, feature_dim)`, the features
    # of b_0 … b_T of stored trajectories under the current model, without gradients (bonuses with
    # `train_on="replay"` train on them).

    def state_dict(self) -> dict: ...

    def load_state_dict(self, state: dict) -> None: ...


def where(mask: torch.Tensor, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return torch.where(mask.view(-1, *([1] * (a.dim() - 1))), a, b)


class Stateless:
    """Shared parts of beliefs that are not trained through the RL loss."""

    trainable = False
    reads_true_task = False
    decodes_reward = False

    def policy_parameters(self) -> list[nn.Parameter]:
        return []

    def sequence_features(self, rollout: Rollout, env_index: torch.Tensor) -> torch.Tensor:
        return rollout.features[:, env_index]

    def train_step(self, trajectories: Trajectories) -> dict[str, float]:
        return {}

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, state: dict) -> None:
        pass


_BELIEFS: Registry[type] = Registry("belief", "beliefs")
_BELIEF_METHODS = (
    "build", "initial_state", "update", "reset_where", "features", "policy_parameters", "sequence_features",
    "train_step", "state_dict", "load_state_dict",
)  # fmt: skip


def register_belief(name: str) -> Callable[[type], type]:
    """Class decorator: makes a belief component selectable as `AgentConfig(belief=name)`.

    The class follows the `Belief` protocol: a classmethod `build(*, state_dim, action_dim, obs_spec, vae,
    recurrent, generator, params)` returning an instance (`params` is the config's `belief_params`, which
    the component validates), and the protocol's methods. Its capabilities `trainable`, `reads_true_task`
    and `decodes_reward` are class attributes (False where the class does not set them).
    """
    if not isinstance(name, str) or not name:
        raise ValueError(f"a belief name must be a non-empty string, got {name!r}")

    def decorator(cls: type) -> type:
        _BELIEFS.check_free(name)
        missing = [m for m in _BELIEF_METHODS if not callable(getattr(cls, m, None))]
        if missing:
            lacks = ", ".join(missing)
            raise TypeError(f"belief {name!r} ({cls.__qualname__}) lacks {lacks} (see agents.beliefs.Belief)")
        for capability in ("trainable", "reads_true_task", "decodes_reward"):
            if not hasattr(cls, capability):
                setattr(cls, capability, False)
        cls.name = name
        return _BELIEFS.add(name, cls, owner=cls.__module__)

    return decorator


def belief_class(name: str) -> type:
    """The belief component registered as `name` (its capabilities are class attributes)."""
    return _BELIEFS.lookup(name)


def list_beliefs() -> list[str]:
    """Registered belief names, sorted."""
    return _BELIEFS.names()


def make_belief(
    name: str,
    *,
    state_dim: int,
    action_dim: int,
    obs_spec: dict,
    vae: VAEConfig,
    recurrent: RecurrentConfig,
    generator: torch.Generator,
    params: dict | None = None,
) -> Belief:
    """Builds the registered belief component `name` for a task with observation spec `obs_spec`."""
    return belief_class(name).build(
        state_dim=state_dim,
        action_dim=action_dim,
        obs_spec=obs_spec,
        vae=vae,
        recurrent=recurrent,
        generator=generator,
        params=dict(params or {}),
    )


def unregister_belief(name: str) -> None:
    """Removes a registered belief component (for tests and interactive sessions)."""
    _BELIEFS.remove(name)


def no_params(name: str, params: dict) -> None:
    """For built-in components, which take no `params`: a clear error if some were given."""
    registry.no_params(f"the {name!r} component", params)
