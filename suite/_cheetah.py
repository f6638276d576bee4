"""What the cheetah meta-tasks share: dm_control's cheetah, a zone around the start, a fast batch.

A cheetah zone task draws task parameters from its prior once per BAMDP episode, resets the cheetah
to a random settled pose at each MDP episode start, and computes each step's reward from the torso's
x-velocity and whether the torso is at least `zone_radius` from where the MDP episode started.
Subclasses (one task per module: `suite.cheetah_dir`, `suite.cheetah_vel`) say what the reward is and
how the exact belief, if there is one, changes — once for the dm_control task and once, vectorised,
for the batch.
"""

from __future__ import annotations

import collections
import logging

import mujoco
import numpy as np
from dm_control.rl import control
from dm_control.suite import cheetah

from hyperstate.suite._mujoco_batch import MujocoBatch
from hyperstate.suite._registry import Coverage, PositionAxis
from hyperstate.suite._seeding import SeedLike, spawn_seeds
from hyperstate.suite.base import Marker, MetaTask, TaskPrior, check_action

# dm_control's cheetah.xml uses a compiler attribute MuJoCo 3.17 deprecates; the warning fires on every
# load and says nothing actionable to users of this suite.
logging.getLogger("absl").addFilter(lambda record: "settotalmass" not in record.getMessage())

PHYSICS_TIMESTEP = 0.01  # set in dm_control's cheetah.xml
N_SUB_STEPS = 5
CONTROL_TIMESTEP = PHYSICS_TIMESTEP * N_SUB_STEPS
EPISODE_LENGTH = 200  # control steps per MDP episode (10 s)
ZONE_RADIUS = 5.0  # metres of zero velocity reward around the start
CTRL_COST_WEIGHT = 0.05
SETTLE_STEPS = 200  # physics steps that let a random initial pose settle (as dm_control's cheetah)
# Hyper-state coverage: 1 m bins of the x-displacement over ±20 m (200 steps at a good gait reach ~15–25 m)
# × 3 bins of the exact belief's last component.
COVERAGE = Coverage("x_displacement", low=-20.0, high=20.0, bins=40, belief_bins=3)


def position_axis(zone_radius: float) -> PositionAxis:
    """What the harness plots the cheetah along: its x-displacement from the MDP episode's start, the
    zone's borders dashed."""
    return PositionAxis(
        "x_displacement",
        "x-displacement from the start (m)",
        symbol="x",
        unit="m",
        region=(-zone_radius, zone_radius) if zone_radius > 0 else None,
        region_name="zone",
    )


class Physics(cheetah.Physics):
    """dm_control's cheetah physics with the torso's horizontal position exposed."""

    def torso_x(self) -> float:
        return float(self.named.data.qpos["rootx"][0])


class CheetahZoneTask(MetaTask):
    """Base of the cheetah meta-tasks: random settled start, zone bookkeeping, control cost.

    Subclasses implement `zone_reward(vx, outside)` (the reward before the control cost) and
    `prior_belief`; they may update `self._belief` in `zone_reward`.
    """

    def __init__(
        self,
        prior: TaskPrior,
        *,
        zone_radius: float = ZONE_RADIUS,
        ctrl_cost_weight: float = CTRL_COST_WEIGHT,
        task: np.ndarray | float | None = None,
        episode_length: int = EPISODE_LENGTH,
        episodes_per_task: int = 1,
        **kwargs,
    ):
        if zone_radius < 0:
            raise ValueError(f"zone_radius must be >= 0, got {zone_radius}")
        if ctrl_cost_weight < 0:
            raise ValueError(f"ctrl_cost_weight must be >= 0, got {ctrl_cost_weight}")
        super().__init__(prior, task=task, episode_length=episode_length, episodes_per_task=episodes_per_task, **kwargs)
        self.zone_radius = float(zone_radius)
        self.ctrl_cost_weight = float(ctrl_cost_weight)
        self._x0 = 0.0
        self._x_before = 0.0
        self._action = np.zeros(0)
        self._action_spec = None

    video_camera = "side"

    def zone_reward(self, vx: float, outside: bool) -> float:
        raise NotImplementedError

    def markers(self, physics: Physics) -> list[Marker]:
        """The zone's two borders as thin red walls across the track."""
        if self.zone_radius == 0:
            return []
        return [
            Marker("box", (self._x0 + side * self.zone_radius, 0.0, 0.4), (0.02, 0.6, 0.4), (0.9, 0.2, 0.2, 0.5))
            for side in (-1.0, 1.0)
        ]

    def initialize_mdp_episode(self, physics: Physics) -> None:
        is_limited = physics.model.jnt_limited == 1
        lower, upper = physics.model.jnt_range[is_limited].T
        physics.data.qpos[is_limited] = self._rng.uniform(lower, upper)
        # Raw mj_step (not physics.step) so that the batched simulator can reproduce it exactly.
        mujoco.mj_step(physics.model.ptr, physics.data.ptr, SETTLE_STEPS)
        physics.data.time = 0.0
        self._x0 = physics.torso_x()

    def action_spec(self, physics: Physics):
        # Built once: dm_control rebuilds it from the model on every call, a cost paid every step here.
        if self._action_spec is None:
            self._action_spec = super().action_spec(physics)
        return self._action_spec

    def before_step(self, action, physics: Physics) -> None:
        spec = self.action_spec(physics)
        self._action = np.clip(check_action(action, spec), spec.minimum, spec.maximum)
        self._x_before = physics.torso_x()
        physics.set_control(self._action)

    def transition_reward(self, physics: Physics) -> float:
        x = physics.torso_x()
        vx = (x - self._x_before) / CONTROL_TIMESTEP
        ctrl_cost = self.ctrl_cost_weight * np.sum(np.square(self._action))
        outside = abs(x - self._x0) >= self.zone_radius
        return self.zone_reward(vx, outside) - ctrl_cost

    def mdp_observation(self, physics: Physics) -> collections.OrderedDict:
        obs = collections.OrderedDict()
        obs["position"] = physics.data.qpos[1:].copy()
        obs["velocity"] = physics.data.qvel.copy()
        obs["x_displacement"] = np.array([physics.torso_x() - self._x0])
        return obs


def environment(task: CheetahZoneTask) -> control.Environment:
    """A dm_control environment of `task` on dm_control's cheetah model."""
    physics = Physics.from_xml_string(*cheetah.get_model_and_assets())
    return control.Environment(physics, task, n_sub_steps=N_SUB_STEPS)


class CheetahZoneBatch(MujocoBatch):
    """`num_envs` copies of a `CheetahZoneTask` on one `mujoco.batch.Batch`, reset together.

    `make_task(seed)` builds one copy's task object. Subclasses implement `zone_reward(vx, outside)`,
    the vectorised reward before the control cost, which may update `self._belief`.
    """

    def __init__(self, num_envs: int, seed: SeedLike, make_task, *, num_threads: int = 0):
        tasks = [make_task(s) for s in spawn_seeds(seed, num_envs)]
        self._physics = Physics.from_xml_string(*cheetah.get_model_and_assets())
        super().__init__(tasks, self._physics.model.ptr, num_threads)
        self.zone_radius = tasks[0].zone_radius
        self.ctrl_cost_weight = tasks[0].ctrl_cost_weight
        self._limited = np.flatnonzero(self._model.jnt_limited == 1)  # all joints have one dof
        self._lower, self._upper = self._model.jnt_range[self._limited].T
        self._x0 = np.zeros(num_envs)

    def zone_reward(self, vx: np.ndarray, outside: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _reset_mdp(self) -> None:
        self._sim.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
        for i, task in enumerate(self._tasks):
            self._qpos[i, self._limited] = task.random.uniform(self._lower, self._upper)
        self._sim.step(nstep=SETTLE_STEPS)
        self._time[:] = 0.0
        self._x0 = self._qpos[:, 0].copy()

    def _transition(self, action: np.ndarray) -> np.ndarray:
        x_before = self._qpos[:, 0].copy()
        self._ctrl[:] = action
        self._step_physics(N_SUB_STEPS)
        x = self._qpos[:, 0]
        vx = (x - x_before) / CONTROL_TIMESTEP
        ctrl_cost = self.ctrl_cost_weight * np.sum(np.square(action), axis=1)
        outside = np.abs(x - self._x0) >= self.zone_radius
        return self.zone_reward(vx, outside) - ctrl_cost

    def _mdp_observation(self) -> dict[str, np.ndarray]:
        return {
            "position": self._qpos[:, 1:].copy(),
            "velocity": self._qvel.copy(),
            "x_displacement": (self._qpos[:, 0] - self._x0)[:, None],
        }

    def _extra_state(self) -> dict:
        return {"x0": self._x0.copy()}

    def _load_extra_state(self, state: dict) -> None:
        self._x0 = state["x0"].copy()
