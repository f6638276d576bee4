"""Quadruped-goal meta-task: dm_control's quadruped must walk to an unknown goal, rewarded only near it.

Task prior: goal g on a circle of radius 2 m around the start, angle ~ Uniform[0, 2π).
Reward per control step (0.02 s): 1 if the torso's horizontal position ends the step within
`goal_radius` (0.5 m) of g, else 0; no control cost (as dm_control's quadruped tasks).
Every MDP episode starts upright at the origin with a random heading, at the lowest height without
contacts (dm_control's quadruped initialisation with the orientation restricted to yaw).
Observations: dm_control's quadruped observations plus `position`, the torso's (x, y) from the start
and `heading` (cos, sin of the torso's yaw), which a navigator needs. No exact belief is exposed: after
an unrewarded step the posterior over the angle is the prior minus an arc, not a fixed-size vector.
Registered without a fast batch: `suite.batch` steps dm_control environments (`LoopBatch`).
"""

from __future__ import annotations

import collections

import numpy as np
from dm_control.rl import control
from dm_control.suite import quadruped

from hyperstate.suite._registry import register
from hyperstate.suite._seeding import SeedLike
from hyperstate.suite.base import Marker, MetaTask, check_action

CONTROL_TIMESTEP = 0.02  # dm_control's quadruped
EPISODE_LENGTH = 500  # control steps per MDP episode (10 s)
GOAL_DISTANCE = 2.0  # radius of the circle of goals (m)
GOAL_RADIUS = 0.5  # the reward is paid within this distance of the goal (m)
FLOOR_SIZE = 6.0  # half-width of the floor (m)


class CircleGoalPrior:
    """Goals on the circle of radius `distance` around the start, uniform in angle."""

    def __init__(self, distance: float = GOAL_DISTANCE):
        self.distance = float(distance)

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        angle = rng.uniform(0.0, 2.0 * np.pi)
        return self.distance * np.array([np.cos(angle), np.sin(angle)])

    def support(self) -> None:
        return None


class QuadrupedGoal(MetaTask):
    """A meta-task where the quadruped must find a goal on a circle; see the module docstring."""

    def __init__(self, *, goal_radius: float = GOAL_RADIUS, goal: np.ndarray | None = None, **kwargs):
        if goal_radius <= 0:
            raise ValueError(f"goal_radius must be > 0, got {goal_radius}")
        super().__init__(CircleGoalPrior(), task=goal, **kwargs)
        self.goal_radius = float(goal_radius)
        self._action_spec = None

    def force_task(self, task) -> None:
        if task is not None and (np.shape(task) != (2,) or not np.all(np.isfinite(task))):
            raise ValueError(f"goal must be a finite (x, y) pair or None, got {task!r}")
        super().force_task(task)

    video_camera = "global"

    def prior_belief(self) -> None:
        return None

    def caption(self) -> str:
        return f"task: goal at ({self._task[0]:.2f}, {self._task[1]:.2f})"

    def markers(self, physics) -> list[Marker]:
        """The rewarded disc around the goal."""
        return [Marker("cylinder", (*self._task, 0.01), (self.goal_radius, 0.01, 0.0), (0.2, 0.7, 0.2, 0.6))]

    def initialize_mdp_episode(self, physics: quadruped.Physics) -> None:
        yaw = self._rng.uniform(0.0, 2.0 * np.pi)
        quadruped._find_non_contacting_height(physics, np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]))

    def action_spec(self, physics):
        if self._action_spec is None:
            self._action_spec = super().action_spec(physics)
        return self._action_spec

    def before_step(self, action, physics: quadruped.Physics) -> None:
        spec = self.action_spec(physics)
        physics.set_control(np.clip(check_action(action, spec), spec.minimum, spec.maximum))

    def transition_reward(self, physics: quadruped.Physics) -> float:
        distance = np.linalg.norm(physics.named.data.xpos["torso", :2] - self._task)
        return float(distance <= self.goal_radius)

    def mdp_observation(self, physics: quadruped.Physics) -> collections.OrderedDict:
        obs = quadruped._common_observations(physics)
        obs["position"] = physics.named.data.xpos["torso", :2].copy()
        forward = physics.named.data.xmat["torso"].reshape(3, 3)[:2, 0]  # the torso's x-axis in the world
        obs["heading"] = forward / max(np.linalg.norm(forward), 1e-9)
        return obs


def goal_metrics(observations, rewards, tasks, **_) -> dict[str, np.ndarray]:
    """Per deployment: `goal_reached` (any rewarded step), `first_goal_step` (1-based, NaN if never),
    `closest_distance` (the torso's closest approach to the goal, m)."""
    reached = (np.asarray(rewards) > 0).any(axis=0)
    distance = np.linalg.norm(observations["position"] - np.asarray(tasks)[None], axis=-1)
    return {
        "goal_reached": reached.astype(float),
        "first_goal_step": np.where(reached, (np.asarray(rewards) > 0).argmax(axis=0) + 1.0, np.nan),
        "closest_distance": distance.min(axis=0),
    }


@register("quadruped_goal_sparse", metrics=goal_metrics, position_keys=("position",))
def quadruped_goal_sparse(
    seed: SeedLike = None,
    *,
    goal_radius: float = GOAL_RADIUS,
    goal: np.ndarray | None = None,
    episodes_per_task: int = 1,
    episode_length: int = EPISODE_LENGTH,
    privileged: bool = False,
) -> control.Environment:
    """`quadruped_goal_sparse`: quadruped walking to a goal on a circle (see suite.quadruped_goal)."""
    physics = quadruped.Physics.from_xml_string(quadruped.make_model(floor_size=FLOOR_SIZE), quadruped.common.ASSETS)
    task = QuadrupedGoal(
        goal_radius=goal_radius,
        goal=goal,
        episode_length=episode_length,
        episodes_per_task=episodes_per_task,
        privileged=privileged,
        random=seed,
    )
    return control.Environment(physics, task, control_timestep=CONTROL_TIMESTEP)
