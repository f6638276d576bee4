"""Cheetah-direction meta-task: run forward or backward, rewarded only outside a zone around the start.

Task prior: direction d in {-1 (backward), +1 (forward)}, 50/50.
Reward per control step (0.05 s): `d * vx - 0.05 * |a|^2` once the torso is at least `zone_radius`
(5 m) from where the MDP episode started, `-0.05 * |a|^2` inside the zone; `vx` is the torso's
x-displacement over the step divided by the step's duration, `a` the action clipped to [-1, 1].
Exact belief [P(backward), P(forward)]: [0.5, 0.5] until the first step that ends outside the zone
(whose reward reveals d), one-hot on d afterwards for the rest of the BAMDP episode.
"""

from __future__ import annotations

import collections
import functools
import logging

import mujoco
import mujoco.batch
import numpy as np
from dm_control.rl import control
from dm_control.suite import cheetah
from dm_env import specs

from suite._batch import BatchStep, check_batch_action
from suite._registry import register
from suite._seeding import SeedLike, spawn_seeds
from suite.base import MetaTask, check_action

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
BACKWARD, FORWARD = -1.0, 1.0


class DirectionPrior:
    """Uniform prior over the running direction; support rows are [backward], [forward]."""

    def __init__(self, p_forward: float = 0.5):
        if not 0.0 <= p_forward <= 1.0:
            raise ValueError(f"p_forward must be in [0, 1], got {p_forward}")
        self.p_forward = p_forward

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return np.array([FORWARD if rng.random() < self.p_forward else BACKWARD])

    def support(self) -> np.ndarray:
        return np.array([[BACKWARD], [FORWARD]])

    def probabilities(self) -> np.ndarray:
        return np.array([1.0 - self.p_forward, self.p_forward])


def one_hot_direction(direction: np.ndarray) -> np.ndarray:
    """Belief rows [P(backward), P(forward)] that put all mass on `direction` (shape (..., 1))."""
    forward = (np.asarray(direction)[..., 0] > 0).astype(np.float64)
    return np.stack([1.0 - forward, forward], axis=-1)


class Physics(cheetah.Physics):
    """dm_control's cheetah physics with the torso's horizontal position exposed."""

    def torso_x(self) -> float:
        return float(self.named.data.qpos["rootx"][0])


class CheetahDirection(MetaTask):
    """A `MetaTask` where the cheetah must find out which way to run; see the module docstring."""

    def __init__(
        self,
        *,
        zone_radius: float = ZONE_RADIUS,
        ctrl_cost_weight: float = CTRL_COST_WEIGHT,
        direction: float | None = None,
        **kwargs,
    ):
        if zone_radius < 0:
            raise ValueError(f"zone_radius must be >= 0, got {zone_radius}")
        super().__init__(DirectionPrior(), task=direction, **kwargs)
        self.zone_radius = float(zone_radius)
        self.ctrl_cost_weight = float(ctrl_cost_weight)
        self._x0 = 0.0
        self._x_before = 0.0
        self._action = np.zeros(0)
        self._action_spec = None

    @property
    def direction(self) -> float:
        """Privileged: the true direction of the current task."""
        return float(self._task[0])

    def force_task(self, task) -> None:
        if task is not None and np.ravel(task).tolist() not in ([BACKWARD], [FORWARD]):
            raise ValueError(f"direction must be -1 (backward), +1 (forward) or None, got {task!r}")
        super().force_task(task)

    def prior_belief(self) -> np.ndarray:
        return self._prior.probabilities()

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
        if outside:
            self._belief = one_hot_direction(self._task)
        return (self.direction * vx if outside else 0.0) - ctrl_cost

    def mdp_observation(self, physics: Physics) -> collections.OrderedDict:
        obs = collections.OrderedDict()
        obs["position"] = physics.data.qpos[1:].copy()
        obs["velocity"] = physics.data.qvel.copy()
        obs["x_displacement"] = np.array([physics.torso_x() - self._x0])
        return obs


def _environment(seed: SeedLike, episodes_per_task: int, episode_length: int, privileged: bool, **task_kwargs):
    physics = Physics.from_xml_string(*cheetah.get_model_and_assets())
    task = CheetahDirection(
        episode_length=episode_length,
        episodes_per_task=episodes_per_task,
        privileged=privileged,
        random=seed,
        **task_kwargs,
    )
    return control.Environment(physics, task, n_sub_steps=N_SUB_STEPS)


class CheetahDirectionBatch:
    """`num_envs` copies of `CheetahDirection` on one `mujoco.batch.Batch`, reset together.

    Every copy has the same horizon, so all copies reach MDP and BAMDP episode ends on the same step.
    """

    def __init__(
        self,
        num_envs: int,
        seed: SeedLike = None,
        *,
        zone_radius: float = ZONE_RADIUS,
        ctrl_cost_weight: float = CTRL_COST_WEIGHT,
        direction: float | None = None,
        episodes_per_task: int = 1,
        episode_length: int = EPISODE_LENGTH,
        privileged: bool = False,
        num_threads: int = 0,
    ):
        # One CheetahDirection per copy holds its prior, forced task and generator; the physics
        # lives in the batch.
        self._tasks = [
            CheetahDirection(
                zone_radius=zone_radius,
                ctrl_cost_weight=ctrl_cost_weight,
                direction=direction,
                episode_length=episode_length,
                episodes_per_task=episodes_per_task,
                privileged=privileged,
                random=s,
            )
            for s in spawn_seeds(seed, num_envs)
        ]
        self.num_envs = num_envs
        self.zone_radius = float(zone_radius)
        self.ctrl_cost_weight = float(ctrl_cost_weight)
        self.episode_length = int(episode_length)
        self.episodes_per_task = int(episodes_per_task)
        self.privileged = privileged
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
        self._direction = np.zeros((num_envs, 1))
        self._belief = np.zeros((num_envs, 2))
        self._x0 = np.zeros(num_envs)
        self._inner_episode = 0
        self._inner_step = 0
        self._started = False

    def observation_spec(self) -> dict[str, specs.Array]:
        return {k: specs.Array(v.shape[1:], v.dtype, name=k) for k, v in self._observation().items()}

    def action_spec(self) -> specs.BoundedArray:
        return self._action_spec

    @property
    def belief(self) -> np.ndarray:
        """Privileged: exact beliefs of all copies, (num_envs, 2)."""
        return self._belief.copy()

    @property
    def task_parameters(self) -> np.ndarray:
        """Privileged: the true directions, (num_envs, 1)."""
        return self._direction.copy()

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
        self._direction = np.stack([task.sample_task() for task in self._tasks])
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
            obs["belief"] = self._belief.copy()
            obs["task"] = self._direction.copy()
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
        self._belief[outside] = one_hot_direction(self._direction[outside])
        reward = np.where(outside, self._direction[:, 0] * vx, 0.0) - ctrl_cost

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
            "direction": self._direction.copy(),
            "belief": self._belief.copy(),
            "x0": self._x0.copy(),
            "counters": (self._inner_episode, self._inner_step, self._started),
        }

    def load_state_dict(self, state: dict) -> None:
        self._sim.state[...] = state["physics"]
        for task, gen_state in zip(self._tasks, state["generators"], strict=True):
            task.random.bit_generator.state = gen_state
        self._direction = state["direction"].copy()
        self._belief = state["belief"].copy()
        self._x0 = state["x0"].copy()
        self._inner_episode, self._inner_step, self._started = state["counters"]

    def close(self) -> None:
        pass


def zone_exploration_metrics(
    observations: dict[str, np.ndarray],
    rewards: np.ndarray,
    tasks: np.ndarray,
    zone_radius: float = ZONE_RADIUS,
    **_: object,
) -> dict[str, np.ndarray]:
    """Deployed-exploration metrics of M deployments, one value per deployment.

    `observations` are the observations each step ended in ((T, M, ...) arrays), `tasks` the true
    directions (M, 1). Per deployment: `left_zone` (ever |x - x0| >= zone), `first_exit_step` (1-based
    BAMDP step of the first exit, NaN if never), `correct_direction` (left, and the last MDP episode
    ends beyond the zone on the rewarded side), `stuck` (left, and the last MDP episode ends back inside
    the zone: the paper's Figure 3 failure), `distance_correct` (direction * final x-displacement).
    """
    x = observations["x_displacement"][..., 0]
    direction = np.asarray(tasks)[:, 0]
    outside = np.abs(x) >= zone_radius
    left = outside.any(axis=0)
    first = np.where(left, outside.argmax(axis=0) + 1.0, np.nan)
    final = x[-1]
    return {
        "left_zone": left.astype(float),
        "first_exit_step": first,
        "correct_direction": (left & (direction * final >= zone_radius)).astype(float),
        "stuck": (left & (np.abs(final) < zone_radius)).astype(float),
        "distance_correct": direction * final,
    }


def _register(name: str, zone_radius: float) -> None:
    def factory(
        seed: SeedLike = None,
        *,
        zone_radius: float = zone_radius,
        ctrl_cost_weight: float = CTRL_COST_WEIGHT,
        direction: float | None = None,
        episodes_per_task: int = 1,
        episode_length: int = EPISODE_LENGTH,
        privileged: bool = False,
    ) -> control.Environment:
        return _environment(
            seed,
            episodes_per_task,
            episode_length,
            privileged,
            zone_radius=zone_radius,
            ctrl_cost_weight=ctrl_cost_weight,
            direction=direction,
        )

    def batch_factory(num_envs: int, seed: SeedLike = None, *, zone_radius: float = zone_radius, **kwargs):
        return CheetahDirectionBatch(num_envs, seed, zone_radius=zone_radius, **kwargs)

    factory.__name__ = factory.__qualname__ = name
    factory.__doc__ = f"`{name}`: cheetah-direction meta-task, zone radius {zone_radius} m (see suite.cheetah_dir)."
    metrics = functools.partial(zone_exploration_metrics, zone_radius=zone_radius)
    register(name, batch=batch_factory, metrics=metrics)(factory)


_register("cheetah_dir_sparse", ZONE_RADIUS)
_register("cheetah_dir", 0.0)
