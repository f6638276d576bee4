"""Building blocks shared by the meta-tasks: task priors and the BAMDP episode structure.

A meta-task is a dm_control `Task` whose parameters (e.g. the running direction) are drawn from a
`TaskPrior` once per BAMDP episode. One dm_env episode spans `episodes_per_task` MDP episodes of the
same task: physics is reset between them, task and belief are not, and the observation key
`inner_episode` holds the index of the current MDP episode.
"""

from __future__ import annotations

import collections
import dataclasses
from typing import Protocol

import numpy as np
from dm_control.suite import base
from dm_env import specs

from hyperstate.suite._seeding import SeedLike, as_generator


@dataclasses.dataclass(frozen=True)
class Marker:
    """A decoration drawn into rendered frames only (never simulated): a MuJoCo geom type name
    ("box", "cylinder", "sphere"), its world position, size and colour."""

    type: str
    pos: tuple[float, float, float]
    size: tuple[float, float, float]
    rgba: tuple[float, float, float, float]


class TaskPrior(Protocol):
    """A distribution over task parameters, sampled with an explicit `numpy.random.Generator`."""

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        """One draw of the task parameters (a 1-D float array)."""

    def support(self) -> np.ndarray | None:
        """The finite support as rows of task parameters, or None for continuous priors."""


class MetaTask(base.Task):
    """Base class of the suite's meta-tasks: prior sampling, belief bookkeeping, BAMDP horizon.

    Subclasses implement `initialize_mdp_episode`, `transition_reward` (reward of the step just
    taken; may update `self._belief`), `mdp_observation` and `prior_belief`.
    """

    def __init__(
        self,
        prior: TaskPrior,
        *,
        episode_length: int,
        episodes_per_task: int,
        task: np.ndarray | None = None,
        privileged: bool = False,
        random: SeedLike = None,
    ):
        super().__init__(random=0)  # dm_control's RandomState is unused: all draws use self._rng
        if int(episode_length) != episode_length or episode_length < 1:
            raise ValueError(f"episode_length must be a positive integer, got {episode_length!r}")
        if int(episodes_per_task) != episodes_per_task or episodes_per_task < 1:
            raise ValueError(f"episodes_per_task must be a positive integer, got {episodes_per_task!r}")
        self._rng = as_generator(random)
        self._prior = prior
        self._forced_task = None
        self.force_task(task)
        self.episode_length = int(episode_length)
        self.episodes_per_task = int(episodes_per_task)
        self.privileged = privileged
        self._task = np.zeros(0)
        self._belief = np.zeros(0)
        self._inner_episode = 0
        self._inner_step = 0

    @property
    def random(self) -> np.random.Generator:
        """The task's random generator (all prior and initial-state draws come from it)."""
        return self._rng

    @property
    def prior(self) -> TaskPrior:
        return self._prior

    @property
    def task_parameters(self) -> np.ndarray:
        """Privileged: the true parameters of the current task."""
        return self._task.copy()

    @property
    def belief(self) -> np.ndarray | None:
        """Privileged: the exact posterior over the prior's support given everything observed so far
        (None for tasks without an exact belief)."""
        return None if self._belief is None else self._belief.copy()

    @property
    def inner_episode(self) -> int:
        return self._inner_episode

    def force_task(self, task: np.ndarray | float | None) -> None:
        """Fixes the task parameters of every following BAMDP episode (None: draw from the prior again)."""
        self._forced_task = None if task is None else np.atleast_1d(np.asarray(task, dtype=np.float64))

    def sample_task(self) -> np.ndarray:
        return self._forced_task.copy() if self._forced_task is not None else self._prior.sample(self._rng)

    # Rendering: which camera videos use, a one-line description of the task, scene decorations.
    video_camera: str | int = 0

    def caption(self) -> str:
        """The current task in words, for video overlays."""
        return "task " + ", ".join(f"{v:.2f}" for v in self._task)

    def markers(self, physics) -> list[Marker]:
        """Decorations of the current task for rendered frames (e.g. the zone's borders)."""
        return []

    # Subclass hooks -----------------------------------------------------------------------------
    def prior_belief(self) -> np.ndarray | None:
        """The belief before anything is observed; None if the task has no exact belief (then the
        privileged observations hold the true task but no `belief`)."""
        raise NotImplementedError

    def initialize_mdp_episode(self, physics) -> None:
        """Resets the physics for a new MDP episode (the task stays)."""
        raise NotImplementedError

    def transition_reward(self, physics) -> float:
        raise NotImplementedError

    def mdp_observation(self, physics) -> collections.OrderedDict:
        raise NotImplementedError

    # dm_control Task interface ------------------------------------------------------------------
    def initialize_episode(self, physics) -> None:
        self._task = self.sample_task()
        self._belief = self.prior_belief()
        self._inner_episode = 0
        self._inner_step = 0
        self.initialize_mdp_episode(physics)
        # base.Task.initialize_episode is not called: it only runs after_step to recolour geoms by
        # reward, which here would count a step that did not happen.

    def after_step(self, physics) -> None:
        self._reward = float(self.transition_reward(physics))
        self._inner_step += 1
        if self._inner_step == self.episode_length and self._inner_episode + 1 < self.episodes_per_task:
            self._inner_episode += 1
            self._inner_step = 0
            with physics.reset_context():
                self.initialize_mdp_episode(physics)

    def get_reward(self, physics) -> float:
        return self._reward

    def get_termination(self, physics) -> float | None:
        # The BAMDP horizon truncates (discount 1.0), it does not terminate.
        if self._inner_step == self.episode_length and self._inner_episode + 1 == self.episodes_per_task:
            return 1.0
        return None

    def observation_spec(self, physics) -> collections.OrderedDict:
        # Shapes of belief and task are known before the first reset: take them from the prior (a
        # throwaway generator, so the task's own stream is untouched).
        obs = self.mdp_observation(physics)
        obs["inner_episode"] = np.zeros(1)
        if self.privileged:
            belief = self.prior_belief()
            if belief is not None:
                obs["belief"] = belief
            obs["task"] = np.asarray(self._prior.sample(np.random.default_rng(0)), dtype=np.float64)
        return collections.OrderedDict((k, specs.Array(v.shape, v.dtype, name=k)) for k, v in obs.items())

    def get_observation(self, physics) -> collections.OrderedDict:
        obs = self.mdp_observation(physics)
        obs["inner_episode"] = np.array([float(self._inner_episode)])
        if self.privileged:
            if self._belief is not None:
                obs["belief"] = self._belief.copy()
            obs["task"] = self._task.copy()
        return obs


def check_action(action, spec) -> np.ndarray:
    """Validates one action against a BoundedArray spec; raises ValueError naming the problem."""
    action = np.asarray(action, dtype=np.float64)
    if action.shape != spec.shape:
        raise ValueError(f"action has shape {action.shape}, expected {spec.shape}")
    if not np.all(np.isfinite(action)):
        raise ValueError(f"action contains NaN or inf: {action}")
    return action
