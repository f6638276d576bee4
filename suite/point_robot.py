"""Point-robot navigation meta-tasks: find a goal on a half circle, rewarded only near it.

The robot is a point mass on a plane, moved by two motors (x, y) against viscous damping, so its
velocity follows the action with a 0.2 s time constant up to 2 m/s (0.1 m per control step of
0.05 s); it starts every MDP episode at rest at the origin, inside a ±1.5 m arena.
Task prior: goal g on the upper half circle of radius 1, angle ~ Uniform[0, π]; with `num_goals` the
prior is uniform over that many evenly spaced angles (0 and π included) and the task exposes an exact
belief over them.
Reward per control step: sparse (`point_robot_sparse`, `point_treasure_sparse`): 1 if the robot ends the
step within `goal_radius` (0.2 m) of g, else 0; dense (`point_robot`): −‖p − g‖.
Exact belief (finite prior only): the prior restricted to the goals whose reward at every visited
position equals the observed one, renormalised — e.g. one rewarded step leaves only the goals within
0.2 m of it, an unrewarded step removes them.
`point_robot_sparse` has the HyperX reference's horizon: 3 MDP episodes of 100 steps per task, so that
what the first episode finds pays in the next two (`episodes_per_task=1` for a single episode).
`point_treasure_sparse`: 4 candidate goals and 2 MDP episodes of 50 steps per task, so exploring the
candidates in episode 1 pays off in episode 2 (the task stays, the robot is reset).
"""

from __future__ import annotations

import collections
import functools

import mujoco
import numpy as np
from dm_control.mujoco import Physics as MjPhysics
from dm_control.rl import control
from dm_control.suite import base as suite_base

from hyperstate.suite._mujoco_batch import MujocoBatch
from hyperstate.suite._registry import TopDownView, register
from hyperstate.suite._seeding import SeedLike, spawn_seeds
from hyperstate.suite.base import Marker, MetaTask, check_action

PHYSICS_TIMESTEP = 0.01
N_SUB_STEPS = 5
CONTROL_TIMESTEP = PHYSICS_TIMESTEP * N_SUB_STEPS
EPISODE_LENGTH = 100  # control steps per MDP episode (5 s)
GOAL_DISTANCE = 1.0  # radius of the half circle of goals (m)
GOAL_RADIUS = 0.2  # the sparse reward is paid within this distance of the goal (m)
ARENA = 1.5  # the slide joints are limited to ±ARENA (m)
TREASURE_GOALS, TREASURE_EPISODE_LENGTH, TREASURE_EPISODES = 4, 50, 2
SPARSE_EPISODES = 3  # MDP episodes per task of point_robot_sparse: the HyperX reference's SparsePointEnv

MODEL_XML = f"""
<mujoco model="point_robot">
  <option timestep="{PHYSICS_TIMESTEP}"/>
  <visual><global offwidth="640" offheight="480"/></visual>
  <default>
    <joint type="slide" damping="5" limited="true" range="-{ARENA} {ARENA}"/>
    <motor gear="10" ctrlrange="-1 1" ctrllimited="true"/>
    <geom contype="0" conaffinity="0"/>
  </default>
  <worldbody>
    <light pos="0 0 4" dir="0 0 -1"/>
    <camera name="top" pos="0 0.5 3.2" xyaxes="1 0 0 0 1 0"/>
    <geom name="floor" type="plane" size="{ARENA + 0.1} {ARENA + 0.1} 0.1" rgba=".85 .85 .85 1"/>
    <site name="goal" type="cylinder" size="{GOAL_RADIUS} 0.002" pos="1 0 0.002" rgba=".2 .7 .2 .6"/>
    <body name="robot" pos="0 0 0.05">
      <joint name="x" axis="1 0 0"/>
      <joint name="y" axis="0 1 0"/>
      <geom name="robot" type="sphere" size="0.05" mass="1" rgba=".8 .3 .3 1"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="x" joint="x"/>
    <motor name="y" joint="y"/>
  </actuator>
</mujoco>
"""


class HalfCircleGoalPrior:
    """Goals on the upper half circle of radius `distance`: uniform angle, or `num_goals` evenly spaced."""

    def __init__(self, distance: float = GOAL_DISTANCE, num_goals: int | None = None):
        if num_goals is not None and (int(num_goals) != num_goals or num_goals < 1):
            raise ValueError(f"num_goals must be a positive integer or None, got {num_goals!r}")
        self.distance = float(distance)
        self.num_goals = None if num_goals is None else int(num_goals)

    def _at(self, angle) -> np.ndarray:
        return self.distance * np.stack([np.cos(angle), np.sin(angle)], axis=-1)

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        if self.num_goals is None:
            return self._at(rng.uniform(0.0, np.pi))
        return self.support()[rng.integers(self.num_goals)]

    def support(self) -> np.ndarray | None:
        if self.num_goals is None:
            return None
        return self._at(np.linspace(0.0, np.pi, self.num_goals) if self.num_goals > 1 else np.array([np.pi / 2]))

    def probabilities(self) -> np.ndarray | None:
        return None if self.num_goals is None else np.full(self.num_goals, 1.0 / self.num_goals)


def goal_reward(position: np.ndarray, goal: np.ndarray, sparse: bool, goal_radius: float = GOAL_RADIUS) -> np.ndarray:
    """Reward of ending a step at `position` (..., 2) when the goal is `goal` (..., 2); broadcasts."""
    distance = np.linalg.norm(np.asarray(position) - np.asarray(goal), axis=-1)
    return (distance <= goal_radius).astype(np.float64) if sparse else -distance


def belief_update(
    belief: np.ndarray, support: np.ndarray, position: np.ndarray, reward: np.ndarray, sparse: bool, goal_radius: float
) -> np.ndarray:
    """Exact Bayes update of beliefs (N, K) over `support` (K, 2) after ending steps at `position` (N, 2) with
    `reward` (N,): rewards are deterministic given the goal, so the likelihood is 1 where the goal would
    have paid exactly this reward and 0 elsewhere."""
    predicted = goal_reward(position[:, None, :], support[None], sparse, goal_radius)  # (N, K)
    posterior = belief * (np.abs(predicted - reward[:, None]) <= 1e-9)
    return posterior / posterior.sum(axis=1, keepdims=True)


class Physics(MjPhysics):
    """Physics of the point robot."""

    def robot_position(self) -> np.ndarray:
        return self.data.qpos[:2].copy()


class PointRobotGoal(MetaTask):
    """A meta-task where the point robot must find a goal on a half circle; see the module docstring."""

    def __init__(
        self,
        *,
        sparse: bool = True,
        goal_radius: float = GOAL_RADIUS,
        num_goals: int | None = None,
        goal: np.ndarray | None = None,
        **kwargs,
    ):
        if goal_radius <= 0:
            raise ValueError(f"goal_radius must be > 0, got {goal_radius}")
        prior = HalfCircleGoalPrior(num_goals=num_goals)
        # The candidate goals the belief is over (None: continuous); set first, force_task checks goals.
        self._support = prior.support()
        super().__init__(prior, task=goal, **kwargs)
        self.sparse = bool(sparse)
        self.goal_radius = float(goal_radius)
        self._action_spec = None

    @property
    def goal(self) -> np.ndarray:
        """Privileged: the true goal of the current task."""
        return self._task.copy()

    def force_task(self, task) -> None:
        if task is not None:
            task = np.asarray(task, dtype=np.float64)
            if task.shape != (2,) or not np.all(np.isfinite(task)):
                raise ValueError(f"goal must be a finite (x, y) pair or None, got {task!r}")
            support = self._support
            if support is not None and not np.any(np.all(np.isclose(support, task), axis=1)):
                raise ValueError(
                    f"goal {task.tolist()} is not one of the prior's {len(support)} goals: {support.tolist()}"
                )
        super().force_task(task)

    video_camera = "top"

    def prior_belief(self) -> np.ndarray | None:
        return self._prior.probabilities()

    def caption(self) -> str:
        return f"task: goal at ({self._task[0]:.2f}, {self._task[1]:.2f})"

    def markers(self, physics: Physics) -> list[Marker]:
        """The candidate goals of a finite prior, as grey discs (the true goal is the model's green site)."""
        support = self._support
        if support is None:
            return []
        return [Marker("cylinder", (*g, 0.001), (self.goal_radius, 0.001, 0.0), (0.5, 0.5, 0.5, 0.4)) for g in support]

    def initialize_episode(self, physics: Physics) -> None:
        super().initialize_episode(physics)
        physics.named.model.site_pos["goal", :2] = self._task  # only drawn, never simulated

    def initialize_mdp_episode(self, physics: Physics) -> None:
        physics.data.qpos[:] = 0.0
        physics.data.qvel[:] = 0.0

    def action_spec(self, physics: Physics):
        if self._action_spec is None:
            self._action_spec = suite_base.Task.action_spec(self, physics)
        return self._action_spec

    def before_step(self, action, physics: Physics) -> None:
        spec = self.action_spec(physics)
        physics.set_control(np.clip(check_action(action, spec), spec.minimum, spec.maximum))

    def transition_reward(self, physics: Physics) -> float:
        position = physics.robot_position()
        reward = float(goal_reward(position, self._task, self.sparse, self.goal_radius))
        if self._belief is not None:
            self._belief = belief_update(
                self._belief[None], self._support, position[None], np.array([reward]), self.sparse, self.goal_radius
            )[0]
        return reward

    def mdp_observation(self, physics: Physics) -> collections.OrderedDict:
        obs = collections.OrderedDict()
        obs["position"] = physics.data.qpos[:2].copy()
        obs["velocity"] = physics.data.qvel[:2].copy()
        return obs


class PointRobotBatch(MujocoBatch):
    """`num_envs` copies of `PointRobotGoal` on one `mujoco.batch.Batch`, reset together."""

    def __init__(self, num_envs: int, seed: SeedLike = None, *, num_threads: int = 0, **task_kwargs):
        tasks = [PointRobotGoal(random=s, **task_kwargs) for s in spawn_seeds(seed, num_envs)]
        super().__init__(tasks, mujoco.MjModel.from_xml_string(MODEL_XML), num_threads)
        self.sparse, self.goal_radius = tasks[0].sparse, tasks[0].goal_radius
        self._support = tasks[0].prior.support()

    def _reset_mdp(self) -> None:
        self._sim.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)  # qpos0 = 0 (the origin), at rest

    def _transition(self, action: np.ndarray) -> np.ndarray:
        self._ctrl[:] = action
        self._step_physics(N_SUB_STEPS)
        position = self._qpos[:, :2].copy()
        reward = goal_reward(position, self._task, self.sparse, self.goal_radius)
        if self._belief is not None:
            self._belief = belief_update(self._belief, self._support, position, reward, self.sparse, self.goal_radius)
        return reward

    def _mdp_observation(self) -> dict[str, np.ndarray]:
        return {"position": self._qpos[:, :2].copy(), "velocity": self._qvel[:, :2].copy()}


def goal_metrics(
    observations: dict[str, np.ndarray],
    rewards: np.ndarray,
    tasks: np.ndarray,
    goal_radius: float = GOAL_RADIUS,
    **_: object,
) -> dict[str, np.ndarray]:
    """Deployed-exploration metrics of M deployments, one value per deployment: `goal_reached` (ever
    within `goal_radius` of the goal), `first_goal_step` (1-based BAMDP step, NaN if never),
    `last_episode_at_goal` (fraction of the last MDP episode's steps ending at the goal: exploitation)."""
    distance = np.linalg.norm(observations["position"] - np.asarray(tasks)[None], axis=-1)  # (T, M)
    at_goal = distance <= goal_radius
    reached = at_goal.any(axis=0)
    # MDP episodes have equal lengths; the step ending one already shows the next one's first observation,
    # so the last MDP episode is the last T / episodes steps, not the steps observed in it.
    episodes = int(observations["inner_episode"].max()) + 1
    last_episode = at_goal[len(at_goal) - len(at_goal) // episodes :]
    return {
        "goal_reached": reached.astype(float),
        "first_goal_step": np.where(reached, at_goal.argmax(axis=0) + 1.0, np.nan),
        "last_episode_at_goal": last_episode.mean(axis=0),
    }


def draw_scene(ax, task: np.ndarray, num_goals: int | None = None) -> None:
    """The arena's walls, the half circle of goals, the candidates of a finite prior, and the task's goal
    with its reward disc."""
    from matplotlib.patches import Circle, Rectangle

    ax.add_patch(Rectangle((-ARENA, -ARENA), 2 * ARENA, 2 * ARENA, fill=False, color="0.35", linewidth=1))
    arc = np.linspace(0.0, np.pi, 100)
    ax.plot(GOAL_DISTANCE * np.cos(arc), GOAL_DISTANCE * np.sin(arc), color="0.7", linewidth=1)
    support = HalfCircleGoalPrior(num_goals=num_goals).support()
    for candidate in () if support is None else support:
        ax.add_patch(Circle(candidate, GOAL_RADIUS, fill=False, color="0.6", linewidth=0.5))
    ax.add_patch(Circle(np.asarray(task)[:2], GOAL_RADIUS, color="tab:green", alpha=0.4))


# The floor, not the walls: the slide joints' limits are soft, so a robot pushing at a wall stands a little
# past it (about 1 cm), and a plot cut at the walls would hide it.
EXTENT = (-ARENA - 0.1, ARENA + 0.1, -ARENA - 0.1, ARENA + 0.1)


def finds_and_returns(final: dict) -> bool:
    """Success: in at least 90 % of deployments the agent found the goal, and it spent at least half of
    the last MDP episode's steps at it on average (the scripted candidate explorer: 100 % and 0.8)."""
    return final.get("goal_reached", 0.0) >= 0.9 and final.get("last_episode_at_goal", 0.0) >= 0.5


def _register(
    name: str,
    *,
    sparse: bool,
    num_goals: int | None,
    episode_length: int,
    episodes_per_task: int,
    reference_task: str | None = None,
) -> None:
    def factory(
        seed: SeedLike = None,
        *,
        goal_radius: float = GOAL_RADIUS,
        num_goals: int | None = num_goals,
        goal: np.ndarray | None = None,
        episodes_per_task: int = episodes_per_task,
        episode_length: int = episode_length,
        privileged: bool = False,
    ) -> control.Environment:
        task = PointRobotGoal(
            sparse=sparse,
            goal_radius=goal_radius,
            num_goals=num_goals,
            goal=goal,
            episode_length=episode_length,
            episodes_per_task=episodes_per_task,
            privileged=privileged,
            random=seed,
        )
        return control.Environment(Physics.from_xml_string(MODEL_XML), task, n_sub_steps=N_SUB_STEPS)

    def batch_factory(
        num_envs: int,
        seed: SeedLike = None,
        *,
        num_goals: int | None = num_goals,
        episodes_per_task: int = episodes_per_task,
        episode_length: int = episode_length,
        **kwargs,
    ):
        return PointRobotBatch(
            num_envs,
            seed,
            sparse=sparse,
            num_goals=num_goals,
            episodes_per_task=episodes_per_task,
            episode_length=episode_length,
            **kwargs,
        )

    factory.__name__ = factory.__qualname__ = name
    factory.__doc__ = f"`{name}`: point-robot goal meta-task (see suite.point_robot)."

    def metrics(observations, rewards, tasks, goal_radius: float = GOAL_RADIUS, **_):
        return goal_metrics(observations, rewards, tasks, goal_radius=goal_radius)

    register(
        name,
        batch=batch_factory,
        metrics=metrics,
        position_keys=("position",),
        reference_task=reference_task,
        success=finds_and_returns if sparse else None,
        top_down=TopDownView("position", EXTENT, functools.partial(draw_scene, num_goals=num_goals)),
    )(factory)


_register(
    "point_robot_sparse",
    sparse=True,
    num_goals=None,
    episode_length=EPISODE_LENGTH,
    episodes_per_task=SPARSE_EPISODES,
    reference_task="point_robot_3ep",  # same observations, prior and horizon, dense reward
)
_register("point_robot", sparse=False, num_goals=None, episode_length=EPISODE_LENGTH, episodes_per_task=1)
# The dense task over point_robot_sparse's horizon: the task-aware reference must see the later MDP
# episodes (the `inner_episode` observation) in training, or it does not know what to do in them.
_register(
    "point_robot_3ep",
    sparse=False,
    num_goals=None,
    episode_length=EPISODE_LENGTH,
    episodes_per_task=SPARSE_EPISODES,
)
_register(
    "point_treasure_sparse",
    sparse=True,
    num_goals=TREASURE_GOALS,
    episode_length=TREASURE_EPISODE_LENGTH,
    episodes_per_task=TREASURE_EPISODES,
)
