"""The part every fast batch shares: N copies of a `MetaTask` on one `mujoco.batch.Batch`, with the
BAMDP horizon bookkeeping (MDP episode resets, BAMDP resets, final observations) and snapshots.

A task's fast batch subclasses `MujocoBatch` and implements three hooks with NumPy over the copies:
`_reset_mdp()` (physics of every copy to a new MDP episode start), `_transition(action)` (step the
physics, return the (N,) rewards, update `self._belief` where the task has one) and
`_mdp_observation()`. It must reproduce the task's dm_control environment exactly; `_transition` steps the
physics with `_step_physics`, which raises dm_control's `PhysicsError` where the environment would.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import mujoco.batch
import numpy as np
from dm_control.rl.control import PhysicsError
from dm_env import specs

from hyperstate.suite._batch import BatchStep, check_batch_action
from hyperstate.suite.base import MetaTask


class MujocoBatch:
    """Base of the fast batches. `tasks[i]` holds copy i's prior, forced task and generator (the physics
    lives in the batch); every copy has the same horizon, so all copies reach MDP and BAMDP episode ends
    on the same step."""

    def __init__(self, tasks: Sequence[MetaTask], model: mujoco.MjModel, num_threads: int = 0):
        self._tasks = list(tasks)
        first = self._tasks[0]
        self.num_envs = len(self._tasks)
        self.episode_length = first.episode_length
        self.episodes_per_task = first.episodes_per_task
        self.privileged = first.privileged
        self._model = model
        self._sim = mujoco.batch.Batch(model, nsim=self.num_envs, nthread=num_threads)
        self._qpos = self._sim.bind("qpos")
        self._qvel = self._sim.bind("qvel")
        self._ctrl = self._sim.bind("ctrl")
        self._time = self._sim.bind("time")
        self._timestep = float(model.opt.timestep)
        low, high = model.actuator_ctrlrange.T
        self._action_spec = specs.BoundedArray((model.nu,), np.float64, low, high, name="action")
        prior_belief = first.prior_belief()
        self._task = np.zeros((self.num_envs, len(first.prior.sample(np.random.default_rng(0)))))
        self._belief = None if prior_belief is None else np.zeros((self.num_envs, len(prior_belief)))
        self._inner_episode = 0
        self._inner_step = 0
        self._started = False

    # Hooks -------------------------------------------------------------------------------------------
    def _reset_mdp(self) -> None:
        raise NotImplementedError

    def _transition(self, action: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _mdp_observation(self) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def _extra_state(self) -> dict:
        """Task-specific arrays a snapshot must hold besides physics, task and belief."""
        return {}

    def _load_extra_state(self, state: dict) -> None:
        pass

    def _step_physics(self, nstep: int, **kwargs) -> None:
        """Steps every copy's physics `nstep` substeps (`mujoco.batch.Batch.step` keyword arguments pass
        through). Raises `PhysicsError`, as dm_control's `Physics.step` does, where a copy's state became
        invalid (NaN, Inf or huge qpos, qvel or qacc): MuJoCo then resets that copy to its initial state
        mid-step, which shows as a clock that did not advance by `nstep` substeps."""
        timestep, clock = self._timestep, self._time.sum()
        self._sim.step(nstep=nstep, **kwargs)
        # Healthy copies all advance by nstep * timestep; one sum keeps the check off the step's time.
        if abs(self._time.sum() - clock - self.num_envs * nstep * timestep) > 0.5 * timestep:
            behind = np.flatnonzero(self._time < self._time.max() - 0.5 * timestep)  # all reset: none behind
            copies = (behind if behind.size else np.arange(self.num_envs)).tolist()
            raise PhysicsError(
                f"physics state became invalid (NaN, Inf or huge qpos, qvel or qacc) in copies {copies}; "
                "MuJoCo reset them mid-step"
            )

    # BatchEnv ----------------------------------------------------------------------------------------
    def observation_spec(self) -> dict[str, specs.Array]:
        return {k: specs.Array(v.shape[1:], v.dtype, name=k) for k, v in self._observation().items()}

    def action_spec(self) -> specs.BoundedArray:
        return self._action_spec

    @property
    def belief(self) -> np.ndarray | None:
        """Privileged: exact beliefs of all copies, (num_envs, B); None for tasks without one."""
        return None if self._belief is None else self._belief.copy()

    @property
    def task_parameters(self) -> np.ndarray:
        """Privileged: the true task parameters, (num_envs, P)."""
        return self._task.copy()

    def set_tasks(self, tasks: np.ndarray | None) -> None:
        """Forces copy i's task to `tasks[i]` from the next reset on (None: sample from the prior again)."""
        if tasks is not None and len(tasks) != self.num_envs:
            raise ValueError(f"need one task per copy ({self.num_envs}), got {len(tasks)}")
        for i, task in enumerate(self._tasks):
            task.force_task(None if tasks is None else tasks[i])

    def _reset_bamdp(self) -> None:
        self._task = np.stack([task.sample_task() for task in self._tasks])
        if self._belief is not None:
            self._belief = np.tile(self._tasks[0].prior_belief(), (self.num_envs, 1))
        self._inner_episode = 0
        self._inner_step = 0
        self._reset_mdp()

    def _observation(self) -> dict[str, np.ndarray]:
        obs = self._mdp_observation()
        obs["inner_episode"] = np.full((self.num_envs, 1), float(self._inner_episode))
        if self.privileged:
            if self._belief is not None:
                obs["belief"] = self._belief.copy()
            obs["task"] = self._task.copy()
        return obs

    def reset(self) -> BatchStep:
        self._reset_bamdp()
        self._started = True
        obs = self._observation()
        n = self.num_envs
        return BatchStep(obs, np.zeros(n), np.ones(n), np.zeros(n, bool), obs)

    def step(self, action: np.ndarray) -> BatchStep:
        if not self._started:
            raise RuntimeError("call reset() before step()")
        spec = self._action_spec
        action = np.clip(check_batch_action(action, self.num_envs, spec), spec.minimum, spec.maximum)
        reward = self._transition(action)
        self._inner_step += 1
        n = self.num_envs
        last = np.zeros(n, bool)
        if self._inner_step == self.episode_length:
            if self._inner_episode + 1 < self.episodes_per_task:
                self._inner_episode += 1
                self._inner_step = 0
                self._reset_mdp()
            else:
                last[:] = True
        obs = final = self._observation()
        if last[0]:
            self._reset_bamdp()
            obs = self._observation()
        return BatchStep(obs, reward, np.ones(n), last, final)

    def state_dict(self) -> dict:
        """Everything needed to continue exactly from here (physics rows, generators, task, belief)."""
        return {
            "physics": np.array(self._sim.state, copy=True),
            "generators": [task.random.bit_generator.state for task in self._tasks],
            "task": self._task.copy(),
            "belief": None if self._belief is None else self._belief.copy(),
            "counters": (self._inner_episode, self._inner_step, self._started),
            **self._extra_state(),
        }

    def load_state_dict(self, state: dict) -> None:
        self._sim.state[...] = state["physics"]
        for task, gen_state in zip(self._tasks, state["generators"], strict=True):
            task.random.bit_generator.state = gen_state
        self._task = state["task"].copy()
        self._belief = None if state["belief"] is None else state["belief"].copy()
        self._inner_episode, self._inner_step, self._started = state["counters"]
        self._load_extra_state(state)

    def close(self) -> None:
        pass
