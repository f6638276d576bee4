"""Quadruped-goal meta-task: dm_control's quadruped must walk to an unknown goal, rewarded only near it.

Task prior: goal g on a circle of radius 2 m around the start, angle ~ Uniform[0, 2π)
(`goal_region="disc"`: uniform in the disc of radius `goal_distance` instead).
Reward per control step (0.02 s): 1 if the torso's horizontal position ends the step within
`goal_radius` (0.5 m) of g, else 0; no control cost (as dm_control's quadruped tasks).
Every MDP episode starts upright at the origin with a random heading, at the lowest height without
contacts (dm_control's quadruped initialisation with the orientation restricted to yaw).
Observations: dm_control's quadruped observations plus `position`, the torso's (x, y) from the start
and `heading` (cos, sin of the torso's yaw), which a navigator needs. No exact belief is exposed: after
an unrewarded step the posterior over the angle is the prior minus an arc, not a fixed-size vector.
`quadruped_antgoal_sparse` is the HyperX reference's sparse AntGoal setting on this quadruped: goals
uniform in the disc of radius 3 m, rewarded within 0.75 m, 6 MDP episodes of 10 s per task. (The
reference pays 1 − distance inside the radius and −0.75 outside, minus control and contact costs, to
an ant; here the reward stays the suite's 1 inside and 0 outside.)
Fast batch: `QuadrupedGoalBatch` (one `mujoco.batch.Batch`), step for step equal to the dm_control
environment, initial-height search and first observation after a reset included.
"""

from __future__ import annotations

import collections
import copy
from collections.abc import Callable
from typing import Literal

import mujoco
import mujoco.batch
import numpy as np
from dm_control.rl import control
from dm_control.suite import quadruped

from hyperstate.suite._mujoco_batch import MujocoBatch
from hyperstate.suite._registry import register
from hyperstate.suite._seeding import SeedLike, spawn_seeds
from hyperstate.suite.base import Marker, MetaTask, check_action
from hyperstate.suite.point_robot import finds_and_returns

CONTROL_TIMESTEP = 0.02  # dm_control's quadruped
EPISODE_LENGTH = 500  # control steps per MDP episode (10 s)
GOAL_DISTANCE = 2.0  # radius of the circle of goals (m)
GOAL_RADIUS = 0.5  # the reward is paid within this distance of the goal (m)
FLOOR_SIZE = 6.0  # half-width of the floor (m)
HEIGHT_STEP = 0.01  # dm_control's _find_non_contacting_height: 1 cm steps up from z = 0
MAX_HEIGHT_ATTEMPTS = 10000  # ... and its limit


def _norms(v: np.ndarray) -> np.ndarray:
    """Euclidean norm of each row of `v` (N, 2). The task and its batch both use this one function, so
    their rewards and headings agree bit for bit whatever the BLAS (a single vector's `np.linalg.norm`
    is a BLAS dot, which a sum of squares over rows does not reproduce on every CPU)."""
    return np.sqrt((v[:, None, :] @ v[:, :, None])[:, 0, 0])


class CircleGoalPrior:
    """Goals on the circle of radius `distance` around the start, uniform in angle."""

    def __init__(self, distance: float = GOAL_DISTANCE):
        self.distance = float(distance)

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        angle = rng.uniform(0.0, 2.0 * np.pi)
        return self.distance * np.array([np.cos(angle), np.sin(angle)])

    def support(self) -> None:
        return None


class DiscGoalPrior:
    """Goals uniform in the disc of radius `distance` around the start (angle first, then radius)."""

    def __init__(self, distance: float):
        self.distance = float(distance)

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        angle = rng.uniform(0.0, 2.0 * np.pi)
        radius = self.distance * np.sqrt(rng.uniform(0.0, 1.0))
        return radius * np.array([np.cos(angle), np.sin(angle)])

    def support(self) -> None:
        return None


GOAL_PRIORS = {"circle": CircleGoalPrior, "disc": DiscGoalPrior}


def goal_prior(region: Literal["circle", "disc"], distance: float) -> CircleGoalPrior | DiscGoalPrior:
    """The goal prior `region` of radius `distance` (m)."""
    if region not in GOAL_PRIORS:
        raise ValueError(f"goal_region must be one of {', '.join(GOAL_PRIORS)}, got {region!r}")
    if not distance > 0:
        raise ValueError(f"goal_distance must be > 0, got {distance}")
    return GOAL_PRIORS[region](distance)


class QuadrupedGoal(MetaTask):
    """A meta-task where the quadruped must find a goal on a circle (or in a disc); see the module docstring."""

    def __init__(
        self,
        *,
        goal_radius: float = GOAL_RADIUS,
        goal: np.ndarray | None = None,
        prior: CircleGoalPrior | DiscGoalPrior | None = None,
        **kwargs,
    ):
        if goal_radius <= 0:
            raise ValueError(f"goal_radius must be > 0, got {goal_radius}")
        super().__init__(prior or CircleGoalPrior(), task=goal, **kwargs)
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
        distance = _norms((physics.named.data.xpos["torso", :2] - self._task)[None])[0]
        return float(distance <= self.goal_radius)

    def mdp_observation(self, physics: quadruped.Physics) -> collections.OrderedDict:
        obs = quadruped._common_observations(physics)
        obs["position"] = physics.named.data.xpos["torso", :2].copy()
        forward = physics.named.data.xmat["torso"].reshape(3, 3)[:2, 0]  # the torso's x-axis in the world
        obs["heading"] = forward / max(_norms(forward[None])[0], 1e-9)
        return obs


def make_physics() -> quadruped.Physics:
    """dm_control's quadruped on a floor of half-width `FLOOR_SIZE`, without walls, ball or terrain."""
    return quadruped.Physics.from_xml_string(quadruped.make_model(floor_size=FLOOR_SIZE), quadruped.common.ASSETS)


class QuadrupedGoalBatch(MujocoBatch):
    """`num_envs` copies of `QuadrupedGoal` on one `mujoco.batch.Batch`, reset together.

    Reproduces dm_control's environment exactly:
    - a control step is 4 `mj_step`s followed by the position and velocity stages at the new state
      (`stage=mjSTAGE_VEL`), which is what dm_control's legacy `Physics.step` (mj_step2, mj_steps,
      mj_step1) leaves in `mjData`: positions and velocity sensors current, acceleration sensors
      (accelerometer, toe forces and torques) from the last substep;
    - an MDP episode start draws each copy's yaw from its task's generator, then runs dm_control's
      `_find_non_contacting_height` loop on a second batch of the model with actuation disabled
      (dm_control's reset forwards so): every copy still in contact is forwarded at a height 1 cm up
      (heights accumulated as dm_control adds them) until it has no contact; that batch's full forward
      gives the first observation, and its state rows become the copies' states. (With all hinges at 0
      and no activation the actuator forces vanish anyway; the flag keeps the match true by construction.)
    """

    def __init__(
        self,
        num_envs: int,
        seed: SeedLike = None,
        *,
        num_threads: int = 0,
        goal_radius: float = GOAL_RADIUS,
        goal: np.ndarray | None = None,
        goal_region: Literal["circle", "disc"] = "circle",
        goal_distance: float = GOAL_DISTANCE,
        episodes_per_task: int = 1,
        episode_length: int = EPISODE_LENGTH,
        privileged: bool = False,
    ):
        prior = goal_prior(goal_region, goal_distance)
        tasks = [
            QuadrupedGoal(
                goal_radius=goal_radius,
                goal=goal,
                prior=prior,
                episode_length=episode_length,
                episodes_per_task=episodes_per_task,
                privileged=privileged,
                random=s,
            )
            for s in spawn_seeds(seed, num_envs)
        ]
        physics = make_physics()
        model = physics.model.ptr
        super().__init__(tasks, model, num_threads)
        self.goal_radius = tasks[0].goal_radius
        self._n_sub_steps = control.compute_n_steps(CONTROL_TIMESTEP, model.opt.timestep)
        # The reset batch: dm_control forwards a reset state with actuation disabled.
        reset_model = copy.copy(model)
        reset_model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_ACTUATION
        self._reset_sim = mujoco.batch.Batch(reset_model, nsim=num_envs, nthread=num_threads)
        self._reset_qpos = self._reset_sim.bind("qpos")
        self._reset_ncon = self._reset_sim.bind("ncon")
        self._act = self._sim.bind("act")
        # Where observations are read: the reset batch's outputs right after a reset, else the batch's.
        self._outputs = {
            sim: (sim.bind("xpos"), sim.bind("xmat"), sim.bind("sensordata")) for sim in (self._sim, self._reset_sim)
        }
        self._source = self._sim

        root = model.joint("root")
        self._root = int(model.jnt_qposadr[root.id])
        self._torso = model.body("torso").id
        hinges = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE)
        self._hinge_qpos, self._hinge_qvel = model.jnt_qposadr[hinges], model.jnt_dofadr[hinges]

        def sensor_columns(*types) -> np.ndarray:  # sensordata columns of these sensor types, by sensor id
            ids = np.flatnonzero(np.isin(model.sensor_type, types))
            return np.concatenate(
                [np.arange(model.sensor_adr[i], model.sensor_adr[i] + model.sensor_dim[i]) for i in ids]
            )

        sensor = mujoco.mjtSensor
        self._velocimeter = sensor_columns(sensor.mjSENS_VELOCIMETER)  # the model's one velocimeter
        self._imu = sensor_columns(sensor.mjSENS_GYRO, sensor.mjSENS_ACCELEROMETER)
        self._force_torque = sensor_columns(sensor.mjSENS_FORCE, sensor.mjSENS_TORQUE)

    def _reset_mdp(self) -> None:
        sim, qpos, root = self._reset_sim, self._reset_qpos, self._root
        sim.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
        for i, task in enumerate(self._tasks):  # as QuadrupedGoal.initialize_mdp_episode, copy by copy
            yaw = task.random.uniform(0.0, 2.0 * np.pi)
            qpos[i, root + 3 : root + 7] = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
        qpos[:, root : root + 2] = 0.0
        z = np.zeros(self.num_envs)
        active = np.arange(self.num_envs)
        attempts = 0
        while active.size:
            qpos[active, root + 2] = z[active]
            sim.forward(ids=active, stage=mujoco.mjtStage.mjSTAGE_POS)  # collisions: ncon
            active = active[self._reset_ncon[active] > 0]
            z[active] += HEIGHT_STEP
            attempts += 1
            if attempts > MAX_HEIGHT_ATTEMPTS:
                raise RuntimeError("Failed to find a non-contacting configuration.")
        sim.forward()  # the full forward of dm_control's reset, actuation disabled
        self._sim.state[...] = sim.state
        self._source = sim

    def _transition(self, action: np.ndarray) -> np.ndarray:
        self._ctrl[:] = action
        self._step_physics(self._n_sub_steps, stage=mujoco.mjtStage.mjSTAGE_VEL)
        self._source = self._sim
        position = self._outputs[self._sim][0][:, self._torso, :2]
        return (_norms(position - self._task) <= self.goal_radius).astype(np.float64)

    def _mdp_observation(self) -> dict[str, np.ndarray]:
        xpos, xmat, sensordata = self._outputs[self._source]
        forward = xmat[:, self._torso, [0, 3]]  # the torso's x-axis in the world, (x, y)
        return {
            "egocentric_state": np.hstack(
                (self._qpos[:, self._hinge_qpos], self._qvel[:, self._hinge_qvel], self._act)
            ),
            "torso_velocity": sensordata[:, self._velocimeter],
            "torso_upright": xmat[:, self._torso, 8].copy(),
            "imu": sensordata[:, self._imu],
            "force_torque": np.arcsinh(sensordata[:, self._force_torque]),
            "position": xpos[:, self._torso, :2].copy(),
            "heading": forward / np.maximum(_norms(forward), 1e-9)[:, None],
        }


def goal_metrics(observations, rewards, tasks, **_) -> dict[str, np.ndarray]:
    """Per deployment: `goal_reached` (any rewarded step), `first_goal_step` (1-based, NaN if never),
    `closest_distance` (the torso's closest approach to the goal, m), `last_episode_at_goal` (fraction of
    the last MDP episode's steps rewarded: exploitation, once the goal is known)."""
    rewarded = np.asarray(rewards) > 0  # (T, M)
    reached = rewarded.any(axis=0)
    distance = np.linalg.norm(observations["position"] - np.asarray(tasks)[None], axis=-1)
    # MDP episodes have equal lengths, so the last one is the last T / episodes steps.
    episodes = int(np.max(observations["inner_episode"])) + 1
    return {
        "goal_reached": reached.astype(float),
        "first_goal_step": np.where(reached, rewarded.argmax(axis=0) + 1.0, np.nan),
        "closest_distance": distance.min(axis=0),
        "last_episode_at_goal": rewarded[len(rewarded) - len(rewarded) // episodes :].mean(axis=0),
    }


def finds_the_goal(final: dict) -> bool:
    """Success on `quadruped_goal_sparse` (one MDP episode): the goal found in at least 90 % of deployments."""
    return final.get("goal_reached", 0.0) >= 0.9


def _register(
    name: str, *, region: str, distance: float, radius: float, episodes: int, success: Callable[[dict], bool]
) -> None:
    def factory(
        seed: SeedLike = None,
        *,
        goal_radius: float = radius,
        goal: np.ndarray | None = None,
        goal_region: Literal["circle", "disc"] = region,
        goal_distance: float = distance,
        episodes_per_task: int = episodes,
        episode_length: int = EPISODE_LENGTH,
        privileged: bool = False,
    ) -> control.Environment:
        task = QuadrupedGoal(
            goal_radius=goal_radius,
            goal=goal,
            prior=goal_prior(goal_region, goal_distance),
            episode_length=episode_length,
            episodes_per_task=episodes_per_task,
            privileged=privileged,
            random=seed,
        )
        return control.Environment(make_physics(), task, control_timestep=CONTROL_TIMESTEP)

    def batch_factory(
        num_envs: int,
        seed: SeedLike = None,
        *,
        goal_radius: float = radius,
        goal_region: Literal["circle", "disc"] = region,
        goal_distance: float = distance,
        episodes_per_task: int = episodes,
        **kwargs,
    ) -> QuadrupedGoalBatch:
        return QuadrupedGoalBatch(
            num_envs,
            seed,
            goal_radius=goal_radius,
            goal_region=goal_region,
            goal_distance=goal_distance,
            episodes_per_task=episodes_per_task,
            **kwargs,
        )

    factory.__name__ = factory.__qualname__ = name
    factory.__doc__ = f"`{name}`: quadruped walking to a goal it must find (see suite.quadruped_goal)."
    register(name, batch=batch_factory, metrics=goal_metrics, position_keys=("position",), success=success)(factory)


_register(
    "quadruped_goal_sparse",
    region="circle",
    distance=GOAL_DISTANCE,
    radius=GOAL_RADIUS,
    episodes=1,
    success=finds_the_goal,
)
# The HyperX reference's sparse AntGoal: goals in a 3 m disc, 0.75 m radius, 6 MDP episodes per task.
# Six MDP episodes: success is the point robot's criterion (the goal found in >= 90 % of deployments, at it
# for half the last MDP episode), a threshold not measured here: the quadruped has no scripted walker.
_register("quadruped_antgoal_sparse", region="disc", distance=3.0, radius=0.75, episodes=6, success=finds_and_returns)
