"""Gymnasium adapter: any registered task as a `gymnasium.Env` with a flat Box observation.

    from hyperstate.suite import gym as suite_gym
    env = suite_gym.make("cheetah_dir_sparse", episodes_per_task=2)
    # The same through Gymnasium's registry, from a fresh interpreter ("module:env_id" imports the module,
    # which registers every suite task as hyperstate/<name>):
    env = gymnasium.make("hyperstate.suite.gym:hyperstate/cheetah_dir_sparse", episodes_per_task=2)

The observation concatenates the task's non-privileged observation keys (in spec order) as float32.
One Gymnasium episode is one BAMDP episode; its end is a truncation (the horizon), never a
termination. `info` carries the privileged `belief` and `task`, for analysis — not for the policy.
`reset(seed=s)` rebuilds the environment through the task's registered factory with seed `s`, so the
same seed gives the same task, initial state and every later draw, for any registered task (including a
user's dm_control task seeded the dm_control way, `random=seed`).
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from hyperstate import suite

PRIVILEGED_KEYS = ("belief", "task")


class MetaTaskEnv(gymnasium.Env):
    """A registered suite task behind the Gymnasium API."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, name: str, render_mode: str | None = None, **kwargs: Any):
        self._kwargs = kwargs
        self._env = suite.load(name, seed=None, privileged=True, **kwargs)
        self.name = name
        self.render_mode = render_mode
        spec = self._env.observation_spec()
        self._keys = [k for k in spec if k not in PRIVILEGED_KEYS]
        size = sum(int(np.prod(spec[k].shape)) for k in self._keys)
        self.observation_space = spaces.Box(-np.inf, np.inf, (size,), np.float32)
        a = self._env.action_spec()
        self.action_space = spaces.Box(a.minimum.astype(np.float32), a.maximum.astype(np.float32), a.shape, np.float32)

    def _flat(self, observation: dict) -> np.ndarray:
        return np.concatenate([np.asarray(observation[k], np.float32).ravel() for k in self._keys])

    @staticmethod
    def _info(observation: dict) -> dict:
        return {k: np.asarray(observation[k]).copy() for k in PRIVILEGED_KEYS if k in observation}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None:
            # A task's randomness lives where its factory put it (suite tasks: a NumPy Generator; dm_control
            # tasks: `random=`): building the environment anew with the seed reseeds all of it.
            self._env.close()
            self._env = suite.load(self.name, seed=seed, privileged=True, **self._kwargs)
        step = self._env.reset()
        return self._flat(step.observation), self._info(step.observation)

    def step(self, action):
        step = self._env.step(np.asarray(action, dtype=np.float64))
        truncated = bool(step.last() and step.discount > 0)
        terminated = bool(step.last() and step.discount == 0)
        return self._flat(step.observation), float(step.reward), terminated, truncated, self._info(step.observation)

    def render(self):
        return self._env.physics.render(height=240, width=320, camera_id=0)

    def close(self):
        self._env.close()


def make(name: str, **kwargs: Any) -> MetaTaskEnv:
    """The Gymnasium environment of registered task `name` (task keyword arguments pass through)."""
    return MetaTaskEnv(name, **kwargs)


def register_all() -> None:
    """Registers every suite task with Gymnasium as `hyperstate/<name>` (run again after adding tasks)."""
    for name in suite.TASKS:
        env_id = f"hyperstate/{name}"
        if env_id not in gymnasium.registry:
            gymnasium.register(env_id, entry_point=MetaTaskEnv, kwargs={"name": name}, disable_env_checker=True)


register_all()
