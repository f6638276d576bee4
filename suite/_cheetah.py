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
import mujoco.batch
import numpy as np
from dm_control.rl import control
from dm_control.suite import cheetah
from dm_env import specs

from suite._batch import BatchStep, check_batch_action
from suite._seeding import SeedLike, spawn_seeds
from suite.base import Marker, MetaTask, TaskPrior, check_action

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


class CheetahZoneBatch:
    """`num_envs` copies of a `CheetahZoneTask` on one `mujoco.batch.Batch`, reset together.

    `make_task(seed)` builds one copy's task object (it holds the copy's prior, forced task and
    generator; the physics lives in the batch). Subclasses implement `zone_reward(vx, outside)`, the
    vectorised reward before the control cost, which may update `self._belief`. Every copy has the
    same horizon, so all copies reach MDP and BAMDP episode ends on the same step.
    """

    def __init__(self, num_envs: int, seed: SeedLike, make_task, *, num_threads: int = 0):
        self._tasks: list[CheetahZoneTask] = [make_task(s) for s in spawn_seeds(seed, num_envs)]
        first = self._tasks[0]
        self.num_envs = num_envs
        self.zone_radius = first.zone_radius
        self.ctrl_cost_weight = first.ctrl_cost_weight
        self.episode_length = first.episode_length
        self.episodes_per_task = first.episodes_per_task
        self.privileged = first.privileged
        self._physics = Physics.from_xml_string(*cheetah.get_model_and_assets())
        model = self._physics.model.ptr
        self._sim = mujoco.batch.Batch(model, nsim=num_envs, nthread=num_threads)
        self._qpos = self._sim.bind("qpos")
        self._qvel = self._sim.bind("qvel")
        self._ctrl = self._sim.bind("ctrl")
        self._time = self._sim.bind("time")
        self._limited = np.flatnonzero(model.jnt_limited == 1)  # all joints have one dof
        self._lower, self._upper = model.jnt_range[self._limited].T
        self._action_spec = specs.BoundedArray(
            (model.nu,), np.float64, model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1], name="action"
        )
        prior_belief = first.prior_belief()
        self._has_belief = prior_belief is not None
        self._task = np.zeros((num_envs, len(first.prior.sample(np.random.default_rng(0)))))
        self._belief = np.zeros((num_envs, 0 if prior_belief is None else len(prior_belief)))
        self._x0 = np.zeros(num_envs)
        self._inner_episode = 0
        self._inner_step = 0
        self._started = False

    def zone_reward(self, vx: np.ndarray, outside: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def observation_spec(self) -> dict[str, specs.Array]:
        return {k: specs.Array(v.shape[1:], v.dtype, name=k) for k, v in self._observation().items()}

    def action_spec(self) -> specs.BoundedArray:
        return self._action_spec

    @property
    def belief(self) -> np.ndarray:
        """Privileged: exact beliefs of all copies, (num_envs, B)."""
        return self._belief.copy()

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

    def _reset_mdp(self) -> None:
        self._sim.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
        for i, task in enumerate(self._tasks):
            self._qpos[i, self._limited] = task.random.uniform(self._lower, self._upper)
        self._sim.step(nstep=SETTLE_STEPS)
        self._time[:] = 0.0
        self._x0 = self._qpos[:, 0].copy()

    def _reset_bamdp(self) -> None:
        self._task = np.stack([task.sample_task() for task in self._tasks])
        if self._has_belief:
            self._belief = np.tile(self._tasks[0].prior_belief(), (self.num_envs, 1))
        self._inner_episode = 0
        self._inner_step = 0
        self._reset_mdp()

    def _observation(self) -> dict[str, np.ndarray]:
        obs = {
            "position": self._qpos[:, 1:].copy(),
            "velocity": self._qvel.copy(),
            "x_displacement": (self._qpos[:, 0] - self._x0)[:, None],
            "inner_episode": np.full((self.num_envs, 1), float(self._inner_episode)),
        }
        if self.privileged:
            if self._has_belief:
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
        x_before = self._qpos[:, 0].copy()
        self._ctrl[:] = action
        self._sim.step(nstep=N_SUB_STEPS)
        x = self._qpos[:, 0]
        vx = (x - x_before) / CONTROL_TIMESTEP
        ctrl_cost = self.ctrl_cost_weight * np.sum(np.square(action), axis=1)
        outside = np.abs(x - self._x0) >= self.zone_radius
        reward = self.zone_reward(vx, outside) - ctrl_cost

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
            "belief": self._belief.copy(),
            "x0": self._x0.copy(),
            "counters": (self._inner_episode, self._inner_step, self._started),
        }

    def load_state_dict(self, state: dict) -> None:
        self._sim.state[...] = state["physics"]
        for task, gen_state in zip(self._tasks, state["generators"], strict=True):
            task.random.bit_generator.state = gen_state
        self._task = state["task"].copy()
        self._belief = state["belief"].copy()
        self._x0 = state["x0"].copy()
        self._inner_episode, self._inner_step, self._started = state["counters"]

    def close(self) -> None:
        pass
