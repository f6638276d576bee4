"""Belief components: what the policy knows about the task beyond the current state.

Every belief follows one protocol. Its state `b_t` summarises everything observed up to s_t; it starts
from a prior at the start of each BAMDP episode and is updated with each transition (a_t, r_t, s_{t+1}).
`features(b_t)` is what the policy and the hyper-state bonus see.

- `none`: no features (a Markov policy on the state).
- `oracle`: the exact belief the task hands over as privileged information (the paper's Belief Oracle).
- `recurrent`: RL²; a GRU trained by the RL loss through time.
- `varibad`: variBAD's VAE; the policy sees the posterior (mean, logvar), detached.
- `task_supervised`: the same encoder trained to predict the true task parameters (Humplik et al. 2019).
- `task_aware`: the true task parameters (privileged): the reference policy that knows the task.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Protocol

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from hyperstate.agents.config import RecurrentConfig, VAEConfig
from hyperstate.agents.naming import unknown_name
from hyperstate.agents.networks import mlp
from hyperstate.agents.rollout import Rollout


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


def _where(mask: torch.Tensor, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return torch.where(mask.view(-1, *([1] * (a.dim() - 1))), a, b)


class _Stateless:
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


class NoBelief(_Stateless):
    """A Markov policy: no belief features."""

    name = "none"

    def __init__(self, num_states: int):
        self.feature_dim = 0

    @classmethod
    def build(cls, *, state_dim, params, **_):
        no_params(cls.name, params)
        return cls(state_dim)

    def initial_state(self, n, obs):
        return torch.zeros(n, 0)

    def update(self, state, transition):
        return state

    def reset_where(self, state, mask, obs):
        return state

    def features(self, state):
        return state


class OracleBelief(_Stateless):
    """The exact belief, read from the task's privileged `belief` observation.

    With `key="task"` it hands over the true task instead: the task-aware reference policy.
    """

    name = "oracle"
    key = "belief"
    missing = "the oracle belief needs a task with an exact belief (privileged `belief` observation)"

    def __init__(self, dim: int):
        self.feature_dim = dim

    @classmethod
    def build(cls, *, obs_spec, params, **_):
        no_params(cls.name, params)
        if cls.key not in obs_spec:
            raise ValueError(cls.missing)
        return cls(int(np.prod(obs_spec[cls.key].shape)))

    def initial_state(self, n, obs):
        return obs[self.key].clone()

    def update(self, state, transition):
        return transition.next_obs[self.key].clone()

    def reset_where(self, state, mask, obs):
        return _where(mask, obs[self.key], state)

    def features(self, state):
        return state


class TaskAwareBelief(OracleBelief):
    """The true task parameters, read from the task's privileged `task` observation: the reference
    policy that knows the task (not a meta-learner)."""

    name = "task_aware"
    key = "task"
    missing = "task_aware needs the task's privileged `task` observation"
    reads_true_task = True


class RecurrentBelief:
    """RL²: a GRU over (s_{t+1}, a_t, r_t) whose hidden state (ReLU) is the policy's task summary.

    The hidden state is kept across MDP episodes and reset only at BAMDP starts; the MDP-episode
    boundary (RL²'s "done" input) reaches the GRU through the `inner_episode` observation in s_{t+1}.
    """

    name = "recurrent"
    trainable = False  # by the RL loss only (its parameters are `policy_parameters`)
    reads_true_task = False
    decodes_reward = False

    @classmethod
    def build(cls, *, state_dim, action_dim, recurrent, params, **_):
        no_params(cls.name, params)
        return cls(state_dim, action_dim, recurrent)

    def __init__(self, state_dim: int, action_dim: int, config: RecurrentConfig):
        self.config = config
        self.feature_dim = config.hidden
        self.embed = nn.ModuleDict(
            {
                "state": nn.Linear(state_dim, config.state_embed),
                "action": nn.Linear(action_dim, config.action_embed),
                "reward": nn.Linear(1, config.reward_embed),
            }
        )
        self.gru = nn.GRU(config.state_embed + config.action_embed + config.reward_embed, config.hidden)
        self.modules = nn.ModuleList([self.embed, self.gru])

    def _input(self, next_state, action, reward):
        return torch.cat(
            [
                F.relu(self.embed["state"](next_state)),
                F.relu(self.embed["action"](action)),
                F.relu(self.embed["reward"](reward)),
            ],
            dim=-1,
        )

    def initial_state(self, n, obs):
        return torch.zeros(n, self.config.hidden)

    def update(self, state, transition):
        x = self._input(transition.next_state, transition.action, transition.reward)
        return self.gru(x[None], state[None])[1][0]

    def reset_where(self, state, mask, obs):
        return _where(mask, torch.zeros_like(state), state)

    def features(self, state):
        return F.relu(state)

    def policy_parameters(self):
        return list(self.modules.parameters())

    def sequence_features(self, rollout, env_index):
        """Re-runs the GRU over the rollout from its stored start state, with gradients.

        BAMDP episodes start on the same step in every env, so the rollout splits into segments
        between starts, each one call of the cuDNN-style sequence GRU.
        """
        h = rollout.belief_state0[env_index]
        inputs = self._input(
            rollout.next_state[:, env_index],
            rollout.actions[:, env_index],
            rollout.rewards[:, env_index, None],
        )
        starts = rollout.starts[:, env_index]
        if not bool((starts.all(dim=1) | ~starts.any(dim=1)).all()):
            raise RuntimeError("BAMDP episodes must start on the same step in every env")
        bounds = [0, *[t for t in torch.nonzero(starts[:, 0]).flatten().tolist() if t > 0], inputs.shape[0]]
        out = []
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            if bool(starts[a, 0]):
                h = torch.zeros_like(h)
            seq, last = self.gru(inputs[a:b], h[None])
            # Features at step t come from the hidden state before consuming transition t.
            out.append(torch.cat([h[None], seq[:-1]]))
            h = last[0]
        return F.relu(torch.cat(out))

    def train_step(self, trajectories):
        return {}

    def state_dict(self):
        return {"modules": self.modules.state_dict()}

    def load_state_dict(self, state):
        self.modules.load_state_dict(state["modules"])


class VariationalEncoder(nn.Module):
    """variBAD's encoder: GRU over embedded (a_t, r_t, s_{t+1}) → Gaussian posterior (mean, logvar)."""

    def __init__(self, state_dim: int, action_dim: int, config: VAEConfig):
        super().__init__()
        self.state_embed = nn.Linear(state_dim, config.state_embed)
        self.action_embed = nn.Linear(action_dim, config.action_embed)
        self.reward_embed = nn.Linear(1, config.reward_embed)
        self.gru = nn.GRU(config.action_embed + config.reward_embed + config.state_embed, config.gru_hidden)
        self.head = nn.Linear(config.gru_hidden, 2 * config.latent_dim)
        self.hidden = config.gru_hidden
        self.latent_dim = config.latent_dim

    def embed(self, action, reward, next_state):
        return torch.cat(
            [
                F.relu(self.action_embed(action)),
                F.relu(self.reward_embed(reward)),
                F.relu(self.state_embed(next_state)),
            ],
            dim=-1,
        )

    def step(self, h, action, reward, next_state):
        """One transition for a batch: h (N, H) → (h', mean, logvar).

        The same computation as `sequence` over one step (identical results), written with plain
        functions (`gru_cell`, `F.linear`): called once per rollout step, module overhead dominates it."""
        embedded = torch.cat(
            [
                F.relu(F.linear(action, self.action_embed.weight, self.action_embed.bias)),
                F.relu(F.linear(reward, self.reward_embed.weight, self.reward_embed.bias)),
                F.relu(F.linear(next_state, self.state_embed.weight, self.state_embed.bias)),
            ],
            dim=-1,
        )
        gru = self.gru
        h = torch.gru_cell(embedded, h, gru.weight_ih_l0, gru.weight_hh_l0, gru.bias_ih_l0, gru.bias_hh_l0)
        mean, logvar = F.linear(h, self.head.weight, self.head.bias).chunk(2, dim=-1)
        return h, mean, logvar

    def sequence(self, actions, rewards, next_states):
        """Posteriors of whole trajectories (B, T, ·) → mean, logvar of shape (B, T+1, latent), prior first."""
        b = actions.shape[0]
        out, _ = self.gru(self.embed(actions, rewards, next_states).transpose(0, 1))
        mean, logvar = self.head(out.transpose(0, 1)).chunk(2, dim=-1)
        zeros = torch.zeros(b, 1, self.latent_dim)
        return torch.cat([zeros, mean], dim=1), torch.cat([zeros, logvar], dim=1)


def gaussian_kl(mean_q, logvar_q, mean_p, logvar_p) -> torch.Tensor:
    """KL(N(mean_q, exp logvar_q) || N(mean_p, exp logvar_p)), summed over the last axis."""
    return 0.5 * torch.sum(
        logvar_p - logvar_q + (logvar_q.exp() + (mean_q - mean_p) ** 2) / logvar_p.exp() - 1.0, dim=-1
    )


def kl_to_previous(mean: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """(B, T+1) KL of each posterior to the one before it, the first to N(0, I) (eq. 7)."""
    prev_mean = torch.cat([torch.zeros_like(mean[:, :1]), mean[:, :-1]], dim=1)
    prev_logvar = torch.cat([torch.zeros_like(logvar[:, :1]), logvar[:, :-1]], dim=1)
    return gaussian_kl(mean, logvar, prev_mean, prev_logvar)


class VariBADBelief:
    """variBAD: the posterior of a VAE over the task, trained with the ELBO of eq. (7)."""

    name = "varibad"
    trainable = True
    reads_true_task = False
    decodes_reward = True

    @classmethod
    def build(cls, *, state_dim, action_dim, vae, generator, params, **_):
        no_params(cls.name, params)
        return cls(state_dim, action_dim, vae, generator)

    def __init__(self, state_dim: int, action_dim: int, config: VAEConfig, seed_generator: torch.Generator):
        self.config = config
        self.feature_dim = 2 * config.latent_dim
        self.encoder = VariationalEncoder(state_dim, action_dim, config)
        self.decoder = self._make_decoder(state_dim, action_dim)
        self.modules = nn.ModuleList([self.encoder, self.decoder])
        self.optimizer = torch.optim.Adam(self.modules.parameters(), lr=config.lr)
        self._gen = seed_generator

    def _make_decoder(self, state_dim: int, action_dim: int) -> nn.Module:
        # Reward decoder p(r_j | z, s_j, a_j, s_{j+1}); state decoder optional.
        c = self.config
        out = 1 + (state_dim if c.decode_state else 0)
        return mlp([c.latent_dim + 2 * state_dim + action_dim, *c.decoder_hidden, out], nn.ReLU)

    # Online use --------------------------------------------------------------------------------
    def initial_state(self, n, obs):
        zeros = torch.zeros(n, self.config.latent_dim)
        return (torch.zeros(n, self.config.gru_hidden), zeros, zeros.clone())

    def update(self, state, transition):
        with torch.no_grad():
            return self.encoder.step(state[0], transition.action, transition.reward, transition.next_state)

    def reset_where(self, state, mask, obs):
        fresh = self.initial_state(len(mask), obs)
        return tuple(_where(mask, f, s) for f, s in zip(fresh, state, strict=True))

    def features(self, state):
        return torch.cat([state[1], state[2]], dim=-1)

    def policy_parameters(self):
        return []

    def sequence_features(self, rollout, env_index):
        return rollout.features[:, env_index]

    def replay_features(self, trajectories: Trajectories) -> torch.Tensor:
        """(B, T+1, F) posteriors of stored trajectories under the current encoder, prior first."""
        with torch.no_grad():
            mean, logvar = self.encoder.sequence(trajectories.actions, trajectories.rewards, trajectories.states[:, 1:])
        return torch.cat([mean, logvar], dim=-1)

    # Training ---------------------------------------------------------------------------------
    def sample_latent(self, mean: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
        noise = torch.randn(mean.shape, generator=self._gen)
        return mean + noise * torch.exp(0.5 * logvar)

    def decode(self, z, state, action, next_state):
        return self.decoder(torch.cat([z, state, action, next_state], dim=-1))

    def reconstruction_error(self, features, state, action, next_state, reward) -> torch.Tensor:
        """Squared error of the reward predicted from a latent sample of the posterior `features`."""
        mean, logvar = features.chunk(2, dim=-1)
        with torch.no_grad():
            pred = self.decode(self.sample_latent(mean, logvar), state, action, next_state)[..., :1]
        return (pred - reward).pow(2).sum(-1)

    def _subsample(self, n: int, k: int) -> torch.Tensor:
        if k <= 0 or k >= n:
            return torch.arange(n)
        return torch.randperm(n, generator=self._gen)[:k].sort().values

    def elbo_terms(self, trajectories: Trajectories) -> tuple[torch.Tensor, torch.Tensor]:
        """(reconstruction loss, KL), each averaged over the chosen ELBO timesteps and the batch."""
        s, a, r = trajectories.states, trajectories.actions, trajectories.rewards
        mean, logvar = self.encoder.sequence(a, r, s[:, 1:])  # (B, T+1, L)
        t_len = a.shape[1]
        kl = kl_to_previous(mean, logvar)  # (B, T+1)
        elbo_t = self._subsample(t_len + 1, self.config.subsample_elbos)
        dec_j = self._subsample(t_len, self.config.subsample_decodes)
        z = self.sample_latent(mean[:, elbo_t], logvar[:, elbo_t])  # (B, E, L)
        b, e = z.shape[:2]
        d = len(dec_j)
        # Every latent decodes every chosen transition of the trajectory (past and future).
        inputs = torch.cat(
            [
                z[:, :, None].expand(b, e, d, z.shape[-1]),
                s[:, dec_j][:, None].expand(b, e, d, s.shape[-1]),
                a[:, dec_j][:, None].expand(b, e, d, a.shape[-1]),
                s[:, dec_j + 1][:, None].expand(b, e, d, s.shape[-1]),
            ],
            dim=-1,
        )
        pred = self.decoder(inputs)
        target = r[:, dec_j][:, None].expand(b, e, d, 1)
        if self.config.decode_state:
            target = torch.cat([target, s[:, dec_j + 1][:, None].expand(b, e, d, s.shape[-1])], dim=-1)
        recon = (pred - target).pow(2).sum(-1).sum(-1).mean()  # sum over decodes, mean over ELBOs and batch
        return recon, kl[:, elbo_t].mean()

    def train_step(self, trajectories):
        recon, kl = self.elbo_terms(trajectories)
        loss = recon + self.config.kl_weight * kl
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        return {"vae/reconstruction": recon.item(), "vae/kl": kl.item(), "vae/loss": loss.item()}

    def state_dict(self):
        return {"modules": self.modules.state_dict(), "optimizer": self.optimizer.state_dict()}

    def load_state_dict(self, state):
        self.modules.load_state_dict(state["modules"])
        self.optimizer.load_state_dict(state["optimizer"])


class TaskSupervisedBelief(VariBADBelief):
    """The variBAD encoder trained to regress the true task parameters from every latent (plus KL)."""

    name = "task_supervised"
    decodes_reward = False

    @classmethod
    def build(cls, *, state_dim, action_dim, obs_spec, vae, generator, params, **_):
        no_params(cls.name, params)
        if "task" not in obs_spec:
            raise ValueError("task_supervised needs the task's privileged `task` observation")
        return cls(state_dim, action_dim, vae, generator, int(np.prod(obs_spec["task"].shape)))

    def __init__(self, state_dim, action_dim, config, seed_generator, task_dim: int):
        self._task_dim = task_dim
        super().__init__(state_dim, action_dim, config, seed_generator)

    def _make_decoder(self, state_dim, action_dim):
        return mlp([self.config.latent_dim, *self.config.decoder_hidden, self._task_dim], nn.ReLU)

    def elbo_terms(self, trajectories):
        s, a, r = trajectories.states, trajectories.actions, trajectories.rewards
        if trajectories.tasks is None:
            raise ValueError("task_supervised needs the task's privileged `task` observation")
        mean, logvar = self.encoder.sequence(a, r, s[:, 1:])
        kl = kl_to_previous(mean, logvar)
        elbo_t = self._subsample(a.shape[1] + 1, self.config.subsample_elbos)
        pred = self.decoder(self.sample_latent(mean[:, elbo_t], logvar[:, elbo_t]))
        error = (pred - trajectories.tasks[:, None]).pow(2).sum(-1).mean()
        return error, kl[:, elbo_t].mean()

    def reconstruction_error(self, features, state, action, next_state, reward):
        raise NotImplementedError("task_supervised has no reward decoder; use the vae_error bonus with varibad")


_BELIEFS: dict[str, type] = {}
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
        if name in _BELIEFS:
            raise ValueError(f"belief {name!r} is already registered (by {_BELIEFS[name].__module__})")
        missing = [m for m in _BELIEF_METHODS if not callable(getattr(cls, m, None))]
        if missing:
            lacks = ", ".join(missing)
            raise TypeError(f"belief {name!r} ({cls.__qualname__}) lacks {lacks} (see agents.beliefs.Belief)")
        for capability in ("trainable", "reads_true_task", "decodes_reward"):
            if not hasattr(cls, capability):
                setattr(cls, capability, False)
        cls.name = name
        _BELIEFS[name] = cls
        return cls

    return decorator


def belief_class(name: str) -> type:
    """The belief component registered as `name` (its capabilities are class attributes)."""
    if name not in _BELIEFS:
        raise unknown_name("belief", name, _BELIEFS, "beliefs")
    return _BELIEFS[name]


def list_beliefs() -> list[str]:
    """Registered belief names, sorted."""
    return sorted(_BELIEFS)


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


def no_params(name: str, params: dict) -> None:
    """For built-in components, which take no `params`: a clear error if some were given."""
    if params:
        raise ValueError(f"the {name!r} component takes no params; got {', '.join(map(repr, params))}")


for _cls in (NoBelief, RecurrentBelief, OracleBelief, VariBADBelief, TaskSupervisedBelief, TaskAwareBelief):
    register_belief(_cls.name)(_cls)
