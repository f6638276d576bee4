"""The rollout: T steps of N environments, as typed, preallocated tensors that collection fills in place.

Everything the learner, the bonuses and the beliefs read from a rollout is a field here (no string keys).
One `Rollout` is allocated per training run and overwritten every iteration, so anything that must outlive
an iteration (trajectory pieces kept for belief training) is copied out of it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch


@dataclasses.dataclass
class Rollout:
    """One rollout. Shapes: T = rollout length, N = envs, S = state, F = belief features, A = actions,
    H = the critic's value heads (1, or 2 with an intrinsic value head)."""

    state: torch.Tensor  # (T, N, S) raw s_t
    policy_state: torch.Tensor  # (T, N, S) s_t normalised as the policy saw it
    next_state: torch.Tensor  # (T, N, S) raw s_{t+1} (the final observation where a BAMDP episode ended)
    features: torch.Tensor  # (T, N, F) belief features b_t the action was chosen with
    next_features: torch.Tensor  # (T, N, F) b_{t+1}, after the transition
    actions: torch.Tensor  # (T, N, A) sampled actions
    logprobs: torch.Tensor  # (T, N) log-probability of the sampled action
    values: torch.Tensor  # (T, N, H) V(s_t, b_t)
    next_values: torch.Tensor  # (T, N, H) V(s_{t+1}, b_{t+1})
    rewards: torch.Tensor  # (T, N) raw extrinsic reward
    lasts: torch.Tensor  # (T, N) 1.0 where the step ended a BAMDP episode
    bootstrap: torch.Tensor  # (T, N) discount of V(s_{t+1}): 0 at terminations, else 1
    starts: torch.Tensor  # (T, N) bool: s_t began a BAMDP episode
    advantages: torch.Tensor  # (T, N) filled by the learner (GAE)
    returns: torch.Tensor  # (T, N, H) filled by the learner: each head's advantages + values
    raw_obs: dict[str, np.ndarray]  # (T, N, ...) each observation key, as the environment returned it
    tasks: np.ndarray | None  # (T, N, P) true task parameters, where the task hands them over
    belief_state0: object = None  # the belief state before the first step (recurrent beliefs re-run from it)

    @classmethod
    def allocate(
        cls,
        t_len: int,
        n: int,
        state_dim: int,
        feature_dim: int,
        action_dim: int,
        obs_spec: dict,
        value_heads: int = 1,
    ) -> Rollout:
        """Zeroed buffers for `t_len` steps of `n` envs; `obs_spec`: {key: (shape, dtype)}."""

        def zeros(*shape: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
            return torch.zeros(t_len, n, *shape, dtype=dtype)

        raw_obs = {k: np.zeros((t_len, n, *shape), np.dtype(dtype)) for k, (shape, dtype) in obs_spec.items()}
        return cls(
            state=zeros(state_dim),
            policy_state=zeros(state_dim),
            next_state=zeros(state_dim),
            features=zeros(feature_dim),
            next_features=zeros(feature_dim),
            actions=zeros(action_dim),
            logprobs=zeros(),
            values=zeros(value_heads),
            next_values=zeros(value_heads),
            rewards=zeros(),
            lasts=zeros(),
            bootstrap=zeros(),
            starts=zeros(dtype=torch.bool),
            advantages=zeros(),
            returns=zeros(value_heads),
            raw_obs=raw_obs,
            tasks=raw_obs.get("task"),
        )

    @property
    def shape(self) -> tuple[int, int]:
        """(T, N)."""
        return tuple(self.rewards.shape)

    def store_step(
        self,
        t: int,
        *,
        obs: dict[str, np.ndarray],
        state: torch.Tensor,
        policy_state: torch.Tensor,
        next_state: torch.Tensor,
        features: torch.Tensor,
        next_features: torch.Tensor,
        action: torch.Tensor,
        logprob: torch.Tensor,
        value: torch.Tensor,
        reward: torch.Tensor,
        last: torch.Tensor,
        bootstrap: torch.Tensor,
        start: torch.Tensor,
    ) -> None:
        """Writes step `t` of every env (`next_values[t]` is the collector's: set at episode ends only)."""
        for k, v in obs.items():
            self.raw_obs[k][t] = v
        self.state[t] = state
        self.policy_state[t] = policy_state
        self.next_state[t] = next_state
        self.features[t] = features
        self.next_features[t] = next_features
        self.actions[t] = action
        self.logprobs[t] = logprob
        self.values[t] = value
        self.rewards[t] = reward
        self.lasts[t] = last
        self.bootstrap[t] = bootstrap
        self.starts[t] = start

    def bootstrap_from(self, final_value: torch.Tensor) -> None:
        """After the last step, given V of the state it ended in: V(s_{t+1}) for steps that did not end an
        episode is the next step's value; only episode ends bootstrap with the discount the environment
        gave (and with the value of their final observation, stored during collection)."""
        ended = self.lasts.bool()
        following = torch.cat([self.values[1:], final_value[None]])
        self.next_values.copy_(torch.where(ended[..., None], self.next_values, following))  # every value head
        self.bootstrap.copy_(torch.where(ended, self.bootstrap, torch.ones_like(self.bootstrap)))

    def compute_returns_and_advantages(self, streams: list[tuple[str, np.ndarray, float]], lam: float) -> dict:
        """GAE of each reward stream (name, (T, N) rewards, discount) against its own value head, in order:
        fills `returns` (per head) and `advantages` (their sum: PPO follows all streams). Returns each
        stream's advantage spread (`advantage_std/<name>`): PPO normalises the summed advantages, so the
        spreads, not the rewards' shares, say which stream steers."""
        lasts = self.lasts.numpy().astype(bool).astype(np.float64)
        advantages = np.zeros_like(streams[0][1])
        log = {}
        for head, (name, rewards, gamma) in enumerate(streams):
            head_advantages, head_returns = compute_gae(
                rewards,
                self.values[..., head].numpy(),
                self.next_values[..., head].numpy(),
                lasts,
                self.bootstrap.numpy(),
                gamma,
                lam,
            )
            advantages = advantages + head_advantages
            log[f"advantage_std/{name}"] = float(head_advantages.std())
            self.returns[..., head] = torch.as_tensor(head_returns, dtype=torch.float32)
        self.advantages.copy_(torch.as_tensor(advantages, dtype=torch.float32))
        return log


def compute_gae(
    rewards: np.ndarray,
    values: np.ndarray,
    next_values: np.ndarray,
    lasts: np.ndarray,
    bootstrap: np.ndarray,
    gamma: float,
    lam: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Generalised advantage estimation over (T, N) arrays.

    `next_values[t]` is V(s_{t+1}) (of the final observation where the episode ended at t),
    `bootstrap[t]` multiplies it: 1 except at terminations (0). Truncated episodes (our BAMDP horizon)
    bootstrap from V(final observation) and the advantage recursion restarts after every `last`.
    Returns (advantages, returns).
    """
    advantages = np.zeros_like(rewards)
    running = np.zeros(rewards.shape[1])
    for t in reversed(range(rewards.shape[0])):
        delta = rewards[t] + gamma * bootstrap[t] * next_values[t] - values[t]
        running = delta + gamma * lam * (1.0 - lasts[t]) * running
        advantages[t] = running
    return advantages, advantages + values
