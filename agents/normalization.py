"""Running statistics for observation, reward and bonus normalisation (appendix C of the paper)."""

from __future__ import annotations

import numpy as np
import torch


class RunningMeanStd:
    """Mean and variance of a stream of batches (parallel Welford / Chan et al.)."""

    def __init__(self, shape: tuple[int, ...] = (), epsilon: float = 1e-4):
        self.mean = np.zeros(shape, np.float64)
        self.var = np.ones(shape, np.float64)
        self.count = epsilon

    def update(self, x: np.ndarray) -> None:
        x = np.asarray(x, np.float64).reshape(-1, *self.mean.shape)
        batch_mean, batch_var, n = x.mean(axis=0), x.var(axis=0), x.shape[0]
        delta = batch_mean - self.mean
        total = self.count + n
        self.mean = self.mean + delta * n / total
        m2 = self.var * self.count + batch_var * n + delta**2 * self.count * n / total
        self.var = m2 / total
        self.count = total

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(self.var + 1e-8)

    def normalize(self, x: np.ndarray | torch.Tensor, clip: float = 10.0):
        if isinstance(x, torch.Tensor):
            mean = torch.as_tensor(self.mean, dtype=x.dtype)
            std = torch.as_tensor(self.std, dtype=x.dtype)
            return torch.clamp((x - mean) / std, -clip, clip)
        return np.clip((x - self.mean) / self.std, -clip, clip)

    def state_dict(self) -> dict:
        return {"mean": self.mean.copy(), "var": self.var.copy(), "count": self.count}

    def load_state_dict(self, state: dict) -> None:
        self.mean, self.var, self.count = state["mean"].copy(), state["var"].copy(), float(state["count"])


class ReturnScaler:
    """Divides a reward stream by the std of its running discounted return (as in PPO/RND).

    One per stream: the extrinsic reward and each bonus get their own (eq. 4 with appendix C).
    """

    def __init__(self, num_envs: int, gamma: float):
        self.gamma = gamma
        self.returns = np.zeros(num_envs)
        self.stats = RunningMeanStd()

    def scale(self, rewards: np.ndarray, lasts: np.ndarray) -> np.ndarray:
        """Scales a (T, N) block of rewards, updating the statistics with it first."""
        discounted = np.empty_like(rewards)
        for t in range(rewards.shape[0]):
            self.returns = self.returns * self.gamma + rewards[t]
            discounted[t] = self.returns
            self.returns = np.where(lasts[t], 0.0, self.returns)
        self.stats.update(discounted.reshape(-1))
        return rewards / self.stats.std

    def state_dict(self) -> dict:
        return {"returns": self.returns.copy(), "stats": self.stats.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        self.returns = state["returns"].copy()
        self.stats.load_state_dict(state["stats"])
