"""What a training run carries between iterations: the `TrainState` (its `state_dict` is the checkpoint),
the unfinished BAMDP episode (`Carry`), the stored whole trajectories for belief training, and the clock
that times the loop's phases."""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np
import torch

from hyperstate.agents import config as config_lib
from hyperstate.agents.beliefs import Trajectories
from hyperstate.agents.normalization import ReturnScaler
from hyperstate.agents.policy import Policy


class PhaseClock:
    """Wall time per phase of an iteration, for the log's `time/<phase>` breakdown (seconds): `mark(name)`
    charges the time since the previous mark to `name`. A few `perf_counter` calls per step; nothing
    it measures feeds back into training, so results do not depend on it."""

    PHASES = ("inference", "physics", "belief", "rollout", "bonus", "returns", "ppo", "belief_training")

    def __init__(self) -> None:
        self.totals = dict.fromkeys(self.PHASES, 0.0)
        self.last = time.perf_counter()

    def start(self) -> None:
        self.last = time.perf_counter()

    def mark(self, phase: str) -> None:
        now = time.perf_counter()
        self.totals[phase] += now - self.last
        self.last = now

    def lap(self) -> dict[str, float]:
        """The breakdown since the previous lap, as log entries; starts the next one."""
        out = {f"time/{phase}": seconds for phase, seconds in self.totals.items()}
        self.totals = dict.fromkeys(self.PHASES, 0.0)
        return out


class TrajectoryBuffer:
    """Whole BAMDP episodes for belief training (FIFO, `capacity` trajectories)."""

    def __init__(self, capacity: int):
        self.capacity = capacity
        self.items: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]] = []

    def add(self, states, actions, rewards, tasks) -> None:
        for i in range(states.shape[1]):
            self.items.append((states[:, i], actions[:, i], rewards[:, i], None if tasks is None else tasks[i]))
        del self.items[: max(0, len(self.items) - self.capacity)]

    def sample(self, n: int, generator: torch.Generator) -> Trajectories:
        idx = torch.randint(len(self.items), (n,), generator=generator).tolist()
        s, a, r, k = zip(*(self.items[i] for i in idx), strict=True)
        tasks = None if k[0] is None else torch.as_tensor(np.stack(k), dtype=torch.float32)
        return Trajectories(
            torch.as_tensor(np.stack(s), dtype=torch.float32),
            torch.as_tensor(np.stack(a), dtype=torch.float32),
            torch.as_tensor(np.stack(r), dtype=torch.float32)[..., None],
            tasks,
        )


@dataclasses.dataclass
class Carry:
    """What one iteration hands the next: the current observation, belief state and episode bookkeeping."""

    obs: dict[str, np.ndarray]
    belief: Any
    is_start: np.ndarray  # (N,) the current observation begins a BAMDP episode
    episode_return: np.ndarray  # (N,) extrinsic return of the unfinished BAMDP episode


@dataclasses.dataclass
class TrainState:
    """Everything a training run needs to continue exactly; `state_dict()` is its checkpoint."""

    task: str
    seed: int
    frames: int  # the run's whole budget (iterations × envs × rollout length); the LR schedule depends on it
    policy: Policy
    optimizer: torch.optim.Optimizer
    env: Any  # the suite.BatchEnv being trained on
    carry: Carry
    ext_scaler: ReturnScaler
    bonus_scalers: list[ReturnScaler]
    trajectories: TrajectoryBuffer
    # The unfinished BAMDP episode's pieces (copies), completed into `trajectories` by a later rollout.
    episode_chunks: list[dict[str, np.ndarray]] = dataclasses.field(default_factory=list)
    history: list[dict] = dataclasses.field(default_factory=list)
    iteration: int = 0

    def identity(self) -> tuple:
        """What a checkpoint must match to resume this run."""
        return (config_lib.to_dict(self.policy.config), self.task, self.seed, self.frames)

    def state_dict(self) -> dict:
        carry = self.carry
        return {
            "config": config_lib.to_dict(self.policy.config),
            "task": self.task,
            "seed": self.seed,
            "frames": self.frames,
            "iteration": self.iteration,
            "modules": self.policy.modules_state(),
            "optimizer": self.optimizer.state_dict(),
            "env": self.env.state_dict(),
            "carry": {
                "obs": carry.obs,
                "belief": carry.belief,
                "is_start": carry.is_start,
                "episode_return": carry.episode_return,
            },
            "episode_chunks": list(self.episode_chunks),
            "history": self.history,
            "ext_scaler": self.ext_scaler.state_dict(),
            "bonus_scalers": [s.state_dict() for s in self.bonus_scalers],
            "buffer": self.trajectories.items,
            "generator": self.policy.generator.get_state(),
            "torch_rng": torch.get_rng_state(),
        }

    def load_state_dict(self, saved: dict) -> None:
        self.policy.load_modules_state(saved["modules"])
        self.optimizer.load_state_dict(saved["optimizer"])
        self.env.load_state_dict(saved["env"])
        self.ext_scaler.load_state_dict(saved["ext_scaler"])
        for scaler, state in zip(self.bonus_scalers, saved["bonus_scalers"], strict=True):
            scaler.load_state_dict(state)
        self.trajectories.items = list(saved["buffer"])
        self.episode_chunks = list(saved["episode_chunks"])
        self.policy.generator.set_state(saved["generator"])
        torch.set_rng_state(saved["torch_rng"])
        self.carry = Carry(**saved["carry"])
        self.history = saved["history"]
        self.iteration = saved["iteration"]
