"""Batched simulators: N copies of a task stepped together, with NumPy arrays in and out.

Training steps thousands of copies per second, where dm_control's per-step Python cost would dominate;
a task's fast batch (raw `mujoco` calls) must reproduce its dm_control environment exactly. `LoopBatch`
is the fallback for tasks that register no fast batch: same interface, dm_control environments inside.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from typing import Protocol

import dm_env
import mujoco
import numpy as np
from dm_env import specs


@dataclasses.dataclass
class BatchStep:
    """What one call to `BatchEnv.step` (or `reset`) returns; every array has the batch as first axis.

    Copies whose BAMDP episode ended with this transition (`last`) are reset at once: `observation`
    is then the first observation of their next BAMDP episode and `final_observation` the one the
    transition ended in (for bootstrapping at truncation). Elsewhere the two are the same arrays.
    """

    observation: dict[str, np.ndarray]
    reward: np.ndarray  # (N,) float64; zeros after reset()
    discount: np.ndarray  # (N,) float64; 1.0 where the episode was truncated by its horizon
    last: np.ndarray  # (N,) bool
    final_observation: dict[str, np.ndarray]


class BatchEnv(Protocol):
    """N copies of a task, auto-resetting at BAMDP episode ends."""

    num_envs: int

    def observation_spec(self) -> dict[str, specs.Array]:
        """Spec of one copy's observation."""

    def action_spec(self) -> specs.BoundedArray:
        """Spec of one copy's action."""

    def reset(self) -> BatchStep:
        """Starts a new BAMDP episode in every copy."""

    def set_tasks(self, tasks: np.ndarray | None) -> None:
        """Forces copy i's task parameters to tasks[i] from the next BAMDP reset (None: the prior)."""

    def step(self, action: np.ndarray) -> BatchStep:
        """Applies `action` of shape (N, *action_spec.shape)."""

    def close(self) -> None:
        """Releases resources."""


def check_batch_action(action: np.ndarray, num_envs: int, spec: specs.BoundedArray) -> np.ndarray:
    """Validates a batched action and returns it as float64; raises ValueError naming the problem."""
    action = np.asarray(action, dtype=np.float64)
    expected = (num_envs, *spec.shape)
    if action.shape != expected:
        raise ValueError(f"action has shape {action.shape}, expected {expected} (num_envs, *action_spec.shape)")
    if not np.all(np.isfinite(action)):
        bad = sorted(set(np.argwhere(~np.isfinite(action))[:, 0].tolist()))
        raise ValueError(f"action contains NaN or inf (in copies {bad[:10]})")
    return action


def _is_plain(value: object) -> bool:
    if value is None or isinstance(value, (bool, int, float, str, np.generic)):
        return True
    if isinstance(value, np.ndarray):
        return not value.dtype.hasobject
    if isinstance(value, (list, tuple)):
        return all(_is_plain(v) for v in value)
    if isinstance(value, dict):
        return all(isinstance(k, str) and _is_plain(v) for k, v in value.items())
    return False


def _task_state(task: object) -> dict:
    """A task's mutable state as plain data: random generators by state, plain attributes by value."""
    state = {}
    for name, value in vars(task).items():
        if isinstance(value, np.random.RandomState):
            state[name] = ("random_state", value.get_state(legacy=False))
        elif isinstance(value, np.random.Generator):
            state[name] = ("generator", value.bit_generator.state)
        elif _is_plain(value):
            state[name] = ("value", copy.deepcopy(value))
    return state


def _load_task_state(task: object, state: dict) -> None:
    for name, (kind, value) in state.items():
        if kind == "random_state":
            getattr(task, name).set_state(value)
        elif kind == "generator":
            getattr(task, name).bit_generator.state = value
        else:
            setattr(task, name, copy.deepcopy(value))


def stack(observations: Sequence[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {k: np.stack([np.asarray(o[k]) for o in observations]) for k in observations[0]}


class LoopBatch:
    """Steps a list of dm_control environments one after the other (slow, but works for any task)."""

    def __init__(self, envs: Sequence[dm_env.Environment]):
        if not envs:
            raise ValueError("LoopBatch needs at least one environment")
        self._envs = list(envs)
        self.num_envs = len(self._envs)

    def observation_spec(self) -> dict[str, specs.Array]:
        return self._envs[0].observation_spec()

    def action_spec(self) -> specs.BoundedArray:
        return self._envs[0].action_spec()

    def reset(self) -> BatchStep:
        obs = stack([env.reset().observation for env in self._envs])
        zeros = np.zeros(self.num_envs)
        return BatchStep(obs, zeros, np.ones(self.num_envs), np.zeros(self.num_envs, bool), obs)

    def step(self, action: np.ndarray) -> BatchStep:
        action = check_batch_action(action, self.num_envs, self.action_spec())
        steps = [env.step(a) for env, a in zip(self._envs, action, strict=True)]
        final = stack([s.observation for s in steps])
        last = np.array([s.last() for s in steps])
        observation = final
        if last.any():
            observation = {k: v.copy() for k, v in final.items()}
            for i in np.flatnonzero(last):
                first = self._envs[i].reset().observation
                for k in observation:
                    observation[k][i] = first[k]
        reward = np.array([s.reward for s in steps], dtype=np.float64)
        discount = np.array([s.discount for s in steps], dtype=np.float64)
        return BatchStep(observation, reward, discount, last, final)

    def set_tasks(self, tasks: np.ndarray | None) -> None:
        if tasks is not None and len(tasks) != self.num_envs:
            raise ValueError(f"need one task per copy ({self.num_envs}), got {len(tasks)}")
        for i, env in enumerate(self._envs):
            env.task.force_task(None if tasks is None else tasks[i])

    def state_dict(self) -> dict:
        """Snapshot of every environment: full MuJoCo integration state, the task's state, step counters.

        A snapshot holds data only (arrays, numbers, strings, random-generator states), so it can be
        saved without pickling objects. Of the task's attributes it keeps random generators (by their
        state) and attributes of plain types; anything else (a prior, a spec) is taken to be fixed once
        the task is constructed."""
        snapshot = []
        for env in self._envs:
            physics = env.physics
            spec = mujoco.mjtState.mjSTATE_INTEGRATION
            state = np.empty(mujoco.mj_stateSize(physics.model.ptr, spec))
            mujoco.mj_getState(physics.model.ptr, physics.data.ptr, state, spec)
            snapshot.append(
                {
                    "physics": state,
                    "task": _task_state(env.task),
                    "counters": (env._step_count, env._reset_next_step),
                }
            )
        return {"envs": snapshot}

    def load_state_dict(self, state: dict) -> None:
        for env, saved in zip(self._envs, state["envs"], strict=True):
            physics = env.physics
            mujoco.mj_setState(
                physics.model.ptr, physics.data.ptr, saved["physics"], mujoco.mjtState.mjSTATE_INTEGRATION
            )
            mujoco.mj_forward(physics.model.ptr, physics.data.ptr)
            _load_task_state(env.task, saved["task"])
            env._step_count, env._reset_next_step = saved["counters"]

    def close(self) -> None:
        for env in self._envs:
            env.close()
