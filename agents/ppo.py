"""PPO (Schulman et al. 2017) for the batched meta-tasks: actor-critic, GAE, clipped update.

Read top to bottom: `ActorCritic` maps (normalised state, belief features) to a Gaussian policy and a
value; `compute_gae` turns a rollout into advantages, bootstrapping at truncations; `ppo_update` runs
the clipped objective over epochs and minibatches. Minibatches are groups of whole env sequences by
default, so that a recurrent belief (RL²) can be re-run through time with gradients (the other beliefs
hand back the features stored in the rollout); `minibatch_unit="transitions"` shuffles single
transitions instead, as the reference code does for feed-forward policies.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
import torch
from torch import nn

from hyperstate.agents.config import PPOConfig
from hyperstate.agents.networks import Embed, layer_plan, mlp, run_plan
from hyperstate.agents.rollout import Rollout, compute_gae  # noqa: F401  (compute_gae: its old home)


@dataclasses.dataclass(frozen=True)
class NetworkStyle:
    """How `ActorCritic` builds its networks (`PPOConfig.network` names one of `NETWORK_STYLES`)."""

    activation: type[nn.Module]  # of the embeddings
    init: str  # of the bodies' linear layers (networks.mlp)
    actor_gain: float  # of the mean head
    critic_gain: float | None  # of the value head (None: PyTorch's default init)
    shared_embeddings: bool  # actor and critic embed their inputs once, together


NETWORK_STYLES = {
    # Each of actor and critic embeds its inputs (Linear + ReLU), orthogonal init, the actor's mean head ×0.01
    # so that the first policy is near zero everywhere.
    "cleanrl": NetworkStyle(nn.ReLU, "orthogonal", actor_gain=0.01, critic_gain=1.0, shared_embeddings=False),
    # The reference code's network: one Linear + tanh embedding per input shared by actor and critic, normc
    # init (rows of norm 5/3, zero biases), the mean head normc ×1 (a first policy whose actions depend on
    # state and belief at full scale), the critic head at PyTorch's default init.
    "reference": NetworkStyle(nn.Tanh, "normc", actor_gain=1.0, critic_gain=None, shared_embeddings=True),
}


class ActorCritic(nn.Module):
    """Actor and critic MLPs over embedded state ⊕ embedded belief features, built in the style
    `config.network` names (`NETWORK_STYLES`). The critic has one output per return it learns
    (`value_heads`: the combined return, or extrinsic and intrinsic)."""

    def __init__(self, state_dim: int, feature_dim: int, action_dim: int, config: PPOConfig, value_heads: int = 1):
        super().__init__()
        style = NETWORK_STYLES[config.network]

        def embeddings() -> tuple[Embed, Embed]:
            return (
                Embed(state_dim, config.embed, activation=style.activation),
                Embed(feature_dim, config.embed, config.feature_embed_gain, activation=style.activation),
            )

        def trunk(embedded: tuple[Embed, Embed], out_dim: int, gain: float | None) -> nn.ModuleDict:
            s, f = embedded
            body = mlp([s.out_dim + f.out_dim, *config.hidden, out_dim], out_gain=gain, init=style.init)
            return nn.ModuleDict({"state": s, "features": f, "body": body})

        # Built in this order (actor, then the critic's own embeddings if any): it fixes the initial weights.
        actor_embeddings = embeddings()
        self.actor = trunk(actor_embeddings, action_dim, style.actor_gain)
        critic_embeddings = actor_embeddings if style.shared_embeddings else embeddings()
        self.critic = trunk(critic_embeddings, value_heads, style.critic_gain)
        self._shared_embeddings = style.shared_embeddings  # `step` then embeds once for both
        self.log_std = nn.Parameter(torch.full((action_dim,), config.init_log_std))
        # The per-step path (`step`) runs the same layers as plain functions.
        parts = ("state", "features", "body")
        self._plans = [[layer_plan(net[part]) for part in parts] for net in (self.actor, self.critic)]

    @staticmethod
    def _run(net: nn.ModuleDict, state: torch.Tensor, features: torch.Tensor) -> torch.Tensor:
        return net["body"](torch.cat([net["state"](state), net["features"](features)], dim=-1))

    def value(self, state: torch.Tensor, features: torch.Tensor) -> torch.Tensor:
        """(..., value heads)."""
        return self._run(self.critic, state, features)

    def distribution(self, state: torch.Tensor, features: torch.Tensor) -> torch.distributions.Normal:
        mean, std = self.mean_std(state, features)
        return torch.distributions.Normal(mean, std)

    def mean_std(self, state: torch.Tensor, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mean = self._run(self.actor, state, features)
        return mean, self.log_std.exp().expand_as(mean)

    def step(self, state: torch.Tensor, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(mean, std, value) for one rollout step: `mean_std` and `value` in one call, the layers run as
        plain functions (`networks.run_plan`; identical results, a third less time at 16 envs)."""
        (actor_state, actor_features, actor_body), (critic_state, critic_features, critic_body) = self._plans
        embedded = torch.cat([run_plan(actor_state, state), run_plan(actor_features, features)], dim=-1)
        mean = run_plan(actor_body, embedded)
        if not self._shared_embeddings:
            embedded = torch.cat([run_plan(critic_state, state), run_plan(critic_features, features)], dim=-1)
        return mean, self.log_std.exp().expand_as(mean), run_plan(critic_body, embedded)


def gaussian_log_prob(noise: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """log N(mean + std·noise | mean, std), summed over action dimensions (cheaper than Normal)."""
    return (-0.5 * noise.pow(2) - std.log() - 0.5 * math.log(2 * math.pi)).sum(-1)


_ROLLOUT_KEYS = ("policy_state", "actions", "logprobs", "advantages", "returns", "values")


def env_minibatches(rollout: Rollout, belief, config: PPOConfig, generator: torch.Generator):
    """Groups of whole env sequences, (T, n, ...) each, the belief's features recomputed through time (a
    belief the RL loss trains: RL²'s GRU)."""
    num_envs = rollout.actions.shape[1]
    per_batch = max(1, num_envs // config.minibatches)
    order = torch.randperm(num_envs, generator=generator)
    for start in range(0, num_envs, per_batch):
        idx = order[start : start + per_batch]
        state, actions, logprobs, adv, returns, values = (getattr(rollout, k)[:, idx] for k in _ROLLOUT_KEYS)
        yield state, belief.sequence_features(rollout, idx), actions, logprobs, adv, returns, values


def transition_minibatches(rollout: Rollout, belief, config: PPOConfig, generator: torch.Generator):
    """All T·N transitions shuffled, (m, ...) each, with the features stored in the rollout (beliefs not
    trained by the RL loss only)."""
    t_len, num_envs = rollout.actions.shape[:2]
    total = t_len * num_envs
    keys = (*_ROLLOUT_KEYS, "features")
    flat = {k: getattr(rollout, k).reshape(total, *getattr(rollout, k).shape[2:]) for k in keys}
    per_batch = max(1, total // config.minibatches)
    order = torch.randperm(total, generator=generator)
    for start in range(0, total, per_batch):
        idx = order[start : start + per_batch]
        state, actions, logprobs, adv, returns, values = (flat[k][idx] for k in _ROLLOUT_KEYS)
        yield state, flat["features"][idx], actions, logprobs, adv, returns, values


MINIBATCHES = {"envs": env_minibatches, "transitions": transition_minibatches}  # PPOConfig.minibatch_unit


def _minibatches(rollout: Rollout, belief, config: PPOConfig, generator: torch.Generator):
    """One epoch's minibatches: (state, features, actions, old log-probs, advantages, returns, old values),
    cut as `config.minibatch_unit` says (`MINIBATCHES`)."""
    return MINIBATCHES[config.minibatch_unit](rollout, belief, config, generator)


def mse_value_loss(value: torch.Tensor, returns: torch.Tensor, old_value: torch.Tensor, clip: float) -> torch.Tensor:
    """0.5 (V − R)²."""
    return 0.5 * (value - returns).pow(2).mean() * value.shape[-1]


def clipped_huber_value_loss(
    value: torch.Tensor, returns: torch.Tensor, old_value: torch.Tensor, clip: float
) -> torch.Tensor:
    """The reference code's: the worse of the Huber losses of V and of V clipped to ±clip around the old V."""
    clipped = old_value + (value - old_value).clamp(-clip, clip)
    huber = nn.functional.smooth_l1_loss
    worst = torch.max(huber(value, returns, reduction="none"), huber(clipped, returns, reduction="none"))
    return 0.5 * worst.mean() * value.shape[-1]


VALUE_LOSSES = {"mse": mse_value_loss, "clipped_huber": clipped_huber_value_loss}  # PPOConfig.value_loss


def value_loss(value: torch.Tensor, returns: torch.Tensor, old_value: torch.Tensor, config: PPOConfig) -> torch.Tensor:
    """`config.value_loss` (`VALUE_LOSSES`) on (..., heads) inputs, the heads' losses summed."""
    return VALUE_LOSSES[config.value_loss](value, returns, old_value, config.clip)


def standardized(adv: torch.Tensor) -> torch.Tensor:
    return (adv - adv.mean()) / (adv.std() + 1e-8)


def unchanged(adv: torch.Tensor) -> torch.Tensor:
    return adv


# PPOConfig.advantage_norm: (applied to the whole rollout's advantages, applied to each minibatch's).
ADVANTAGE_NORMS = {"batch": (standardized, unchanged), "minibatch": (unchanged, standardized)}


def ppo_update(
    model: ActorCritic,
    belief,
    optimizer: torch.optim.Optimizer,
    rollout: Rollout,
    config: PPOConfig,
    generator: torch.Generator,
) -> dict[str, float]:
    """Clipped-objective PPO epochs over minibatches (`_minibatches`); returns mean losses."""
    for_rollout, for_minibatch = ADVANTAGE_NORMS[config.advantage_norm]
    minibatches, loss_of_value = MINIBATCHES[config.minibatch_unit], VALUE_LOSSES[config.value_loss]
    rollout = copy.copy(rollout)  # the normalised advantages replace the rollout's own in this copy only
    rollout.advantages = for_rollout(rollout.advantages)
    params = [p for group in optimizer.param_groups for p in group["params"]]
    stats: dict[str, list[float]] = {
        "policy_loss": [],
        "value_loss": [],
        "entropy": [],
        "approx_kl": [],
        "clip_fraction": [],
    }
    for _ in range(config.epochs):
        for state, features, actions, old_logp, adv, returns, old_values in minibatches(
            rollout, belief, config, generator
        ):
            dist = model.distribution(state, features)
            logp = dist.log_prob(actions).sum(-1)
            log_ratio = logp - old_logp
            ratio = log_ratio.exp()
            adv = for_minibatch(adv)
            policy_loss = torch.max(-adv * ratio, -adv * ratio.clamp(1 - config.clip, 1 + config.clip)).mean()
            v_loss = loss_of_value(model.value(state, features), returns, old_values, config.clip)
            entropy = dist.entropy().sum(-1).mean()
            loss = policy_loss + config.value_coef * v_loss - config.entropy_coef * entropy
            optimizer.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(params, config.max_grad_norm)
            optimizer.step()
            with torch.no_grad():
                stats["policy_loss"].append(float(policy_loss))
                stats["value_loss"].append(float(v_loss))
                stats["entropy"].append(float(entropy))
                stats["approx_kl"].append(float(((ratio - 1) - log_ratio).mean()))
                stats["clip_fraction"].append(float(((ratio - 1).abs() > config.clip).float().mean()))
    return {f"ppo/{k}": float(np.mean(v)) for k, v in stats.items()}
