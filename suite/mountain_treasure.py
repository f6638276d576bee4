"""Mountain Treasure: climb a mountain to read where the treasure is, or search the circle it lies on.

A point walks on a plane: each control step moves it by `STEP_SIZE` · clip(a, −1, 1) (a kinematic body:
the task sets its position, MuJoCo only draws it), clipped to the box [−1.5, 1.5]². Every MDP episode
starts at (0, −1) and lasts 100 steps.
Task prior: the treasure lies on the circle of radius 1 around the mountain top (0, 0), at an angle
~ Uniform[0, 2π); with `num_goals` the prior is uniform over that many evenly spaced angles (0 included)
and the task exposes an exact belief over them.
Reward per control step, where the step ends (d = distance to the top):
- on the mountain (d ≤ 0.5): `mountain_height` · (d − 0.5) − `step_penalty`: the higher, the dearer;
- within 0.1 of the treasure: `treasure_reward`;
- elsewhere: −`step_penalty` · max(1, d), so that walking away from the circle costs more.
Observations: `position`, and `treasure_map`: the treasure's position while the point stands within 0.1
of the top, zeros elsewhere.
Exact belief (finite prior only): uniform; one-hot once the map is read; candidates visited without the
treasure's reward are ruled out (and a rewarded step leaves only the candidates within 0.1 of it).
The Bayes-optimal strategy climbs (a cost), reads the map and walks straight to the treasure; a
meta-learner that does not explore walks the circle instead.
`mountain_treasure_k8_sparse` is the finite-prior variant (8 candidates). `mountain_treasure` and
`mountain_treasure_k8` are the dense counterparts the task-aware reference learns on: reward −‖p − treasure‖.

The constants are the HyperX reference's `TreasureHunt-v0` as registered there (treasure 10, step
penalty 5, height 1); its class defaults (1 and 1) are `treasure_reward=1, step_penalty=1`.
"""

from __future__ import annotations

import collections
import dataclasses
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

EPISODE_LENGTH = 100  # control steps per MDP episode
STEP_SIZE = 0.1  # metres moved per step at full action
ARENA = 1.5  # positions are clipped to [−ARENA, ARENA]²
START = (0.0, -1.0)
MOUNTAIN_RADIUS = 0.5  # the climb costs within this distance of the top
TOP_RADIUS = 0.1  # the map is read strictly within this distance of the top
TREASURE_DISTANCE = 1.0  # radius of the circle the treasure lies on
TREASURE_RADIUS = 0.1  # the treasure pays within this distance
MOUNTAIN_HEIGHT = 1.0
TREASURE_REWARD = 10.0
STEP_PENALTY = 5.0
DEFAULT_GOALS = 8  # candidates of the registered finite-prior variant

MODEL_XML = f"""
<mujoco model="mountain_treasure">
  <option timestep="0.01"/>
  <visual><global offwidth="640" offheight="480"/></visual>
  <default>
    <joint type="slide" limited="false"/>
    <!-- gear 0: the actuators only declare the action space; the task moves the body (kinematic) -->
    <motor gear="0" ctrlrange="-1 1" ctrllimited="true"/>
    <geom contype="0" conaffinity="0"/>
  </default>
  <worldbody>
    <light pos="0 0 4" dir="0 0 -1"/>
    <camera name="top" pos="0 0 4.2" xyaxes="1 0 0 0 1 0"/>
    <geom name="floor" type="plane" size="{ARENA + 0.1} {ARENA + 0.1} 0.1" rgba=".85 .85 .85 1"/>
    <geom name="mountain" type="cylinder" size="{MOUNTAIN_RADIUS} 0.002" pos="0 0 0.002" rgba=".55 .45 .35 .6"/>
    <geom name="top" type="cylinder" size="{TOP_RADIUS} 0.003" pos="0 0 0.003" rgba=".35 .25 .15 .9"/>
    <site name="treasure" type="cylinder" size="{TREASURE_RADIUS} 0.004" pos="1 0 0.004" rgba=".9 .75 .1 .9"/>
    <body name="walker" pos="0 0 0.05">
      <joint name="x" axis="1 0 0"/>
      <joint name="y" axis="0 1 0"/>
      <geom name="walker" type="sphere" size="0.05" mass="1" rgba=".8 .3 .3 1"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="x" joint="x"/>
    <motor name="y" joint="y"/>
  </actuator>
</mujoco>
"""


class TreasurePrior:
    """Treasures on the circle of radius `distance` around the top: uniform angle, or `num_goals` evenly
    spaced angles k · 2π / num_goals."""

    def __init__(self, distance: float = TREASURE_DISTANCE, num_goals: int | None = None):
        if num_goals is not None and (int(num_goals) != num_goals or num_goals < 1):
            raise ValueError(f"num_goals must be a positive integer or None, got {num_goals!r}")
        self.distance = float(distance)
        self.num_goals = None if num_goals is None else int(num_goals)

    def _at(self, angle) -> np.ndarray:
        return self.distance * np.stack([np.cos(angle), np.sin(angle)], axis=-1)

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        if self.num_goals is None:
            return self._at(rng.uniform(0.0, 2.0 * np.pi))
        return self.support()[rng.integers(self.num_goals)]

    def support(self) -> np.ndarray | None:
        if self.num_goals is None:
            return None
        return self._at(2.0 * np.pi * np.arange(self.num_goals) / self.num_goals)

    def probabilities(self) -> np.ndarray | None:
        return None if self.num_goals is None else np.full(self.num_goals, 1.0 / self.num_goals)


@dataclasses.dataclass(frozen=True)
class TreasureRewards:
    """The reward's three numbers (see the module docstring)."""

    treasure_reward: float = TREASURE_REWARD
    step_penalty: float = STEP_PENALTY
    mountain_height: float = MOUNTAIN_HEIGHT


def walk(position: np.ndarray, action: np.ndarray) -> np.ndarray:
    """Where steps from `position` (..., 2) with `action` (..., 2) end: the reference's motion."""
    return np.clip(position + STEP_SIZE * np.clip(action, -1.0, 1.0), -ARENA, ARENA)


def _distance(a: np.ndarray, b) -> np.ndarray:
    """Euclidean distance over the last axis (size 2) of broadcast `a` and `b`."""
    d = np.asarray(a) - b
    return np.hypot(d[..., 0], d[..., 1])


def treasure_reward(position: np.ndarray, treasure: np.ndarray, rewards: TreasureRewards, sparse: bool = True):
    """Reward of ending a step at `position` (..., 2) when the treasure is at `treasure` (..., 2); broadcasts."""
    to_treasure = _distance(position, treasure)
    if not sparse:
        return -to_treasure
    return _sparse_reward(_distance(position, 0.0), to_treasure, rewards)


def _sparse_reward(to_top: np.ndarray, to_treasure: np.ndarray, rewards: TreasureRewards) -> np.ndarray:
    climb = rewards.mountain_height * (to_top - MOUNTAIN_RADIUS) - rewards.step_penalty
    away = -rewards.step_penalty * np.maximum(1.0, to_top)
    return np.where(
        to_top <= MOUNTAIN_RADIUS, climb, np.where(to_treasure <= TREASURE_RADIUS, rewards.treasure_reward, away)
    )


def on_top(position: np.ndarray) -> np.ndarray:
    """Whether steps ending at `position` (..., 2) read the map."""
    return _distance(position, 0.0) < TOP_RADIUS


def treasure_map(position: np.ndarray, treasure: np.ndarray) -> np.ndarray:
    """The `treasure_map` observation (..., 2): the treasure on the top, zeros elsewhere."""
    return np.where(on_top(position)[..., None], treasure, 0.0)


def belief_update(
    belief: np.ndarray,
    support: np.ndarray,
    position: np.ndarray,
    reward: np.ndarray,
    seen_map: np.ndarray,
    rewards: TreasureRewards,
    sparse: bool = True,
) -> np.ndarray:
    """Exact Bayes update of beliefs (N, K) over `support` (K, 2) after steps ending at `position` (N, 2)
    with `reward` (N,) and observation `seen_map` (N, 2). Reward and map are deterministic given the
    treasure, so the likelihood is 1 where a candidate would have given exactly what was observed."""
    return _belief_update(belief, support, position, _distance(position, 0.0), reward, seen_map, rewards, sparse)


def _belief_update(belief, support, position, to_top, reward, seen_map, rewards, sparse) -> np.ndarray:
    to_candidates = _distance(position[:, None, :], support[None])  # (N, K)
    predicted = _sparse_reward(to_top[:, None], to_candidates, rewards) if sparse else -to_candidates
    likely = np.abs(predicted - reward[:, None]) <= 1e-9
    read = to_top < TOP_RADIUS  # (N,): the map was read
    if read.any():
        matches_map = (np.abs(support[None] - seen_map[:, None, :]) <= 1e-9).all(axis=-1)  # (N, K)
        likely &= ~read[:, None] | matches_map
    posterior = belief * likely
    return posterior / posterior.sum(axis=1, keepdims=True)


class Physics(MjPhysics):
    """Physics of the walker (kinematic: the task writes its position)."""

    def position(self) -> np.ndarray:
        return self.data.qpos[:2].copy()


class MountainTreasure(MetaTask):
    """The Mountain Treasure meta-task; see the module docstring."""

    def __init__(
        self,
        *,
        sparse: bool = True,
        rewards: TreasureRewards = TreasureRewards(),
        num_goals: int | None = None,
        treasure: np.ndarray | None = None,
        **kwargs,
    ):
        prior = TreasurePrior(num_goals=num_goals)
        self._support = prior.support()  # set first: force_task checks treasures against it
        super().__init__(prior, task=treasure, **kwargs)
        self.sparse = bool(sparse)
        self.rewards = rewards
        self._action_spec = None

    def force_task(self, task) -> None:
        if task is not None:
            task = np.asarray(task, dtype=np.float64)
            if task.shape != (2,) or not np.all(np.isfinite(task)):
                raise ValueError(f"treasure must be a finite (x, y) pair or None, got {task!r}")
            support = self._support
            if support is not None and not np.any(np.all(np.isclose(support, task), axis=1)):
                raise ValueError(f"treasure {task.tolist()} is not one of the prior's {len(support)} candidates")
        super().force_task(task)

    video_camera = "top"

    def prior_belief(self) -> np.ndarray | None:
        return self._prior.probabilities()

    def caption(self) -> str:
        return f"task: treasure at ({self._task[0]:.2f}, {self._task[1]:.2f})"

    def markers(self, physics: Physics) -> list[Marker]:
        """The candidate treasures of a finite prior, as grey discs (the true one is the model's site)."""
        if self._support is None:
            return []
        grey = (0.5, 0.5, 0.5, 0.5)
        return [Marker("cylinder", (*g, 0.001), (TREASURE_RADIUS, 0.001, 0.0), grey) for g in self._support]

    def initialize_episode(self, physics: Physics) -> None:
        super().initialize_episode(physics)
        physics.named.model.site_pos["treasure", :2] = self._task  # only drawn

    def initialize_mdp_episode(self, physics: Physics) -> None:
        physics.data.qpos[:] = START
        physics.data.qvel[:] = 0.0

    def action_spec(self, physics: Physics):
        if self._action_spec is None:
            self._action_spec = suite_base.Task.action_spec(self, physics)
        return self._action_spec

    def before_step(self, action, physics: Physics) -> None:
        # The walker is kinematic: its step is the reference's, written here; the physics step that
        # follows leaves it in place (gear-0 motors, no velocity, gravity across the slides).
        physics.data.qpos[:] = walk(physics.data.qpos[:2], check_action(action, self.action_spec(physics)))

    def transition_reward(self, physics: Physics) -> float:
        position = physics.position()
        reward = float(treasure_reward(position, self._task, self.rewards, self.sparse))
        if self._belief is not None:
            self._belief = belief_update(
                self._belief[None],
                self._support,
                position[None],
                np.array([reward]),
                treasure_map(position, self._task)[None],
                self.rewards,
                self.sparse,
            )[0]
        return reward

    def mdp_observation(self, physics: Physics) -> collections.OrderedDict:
        position = physics.position()
        obs = collections.OrderedDict()
        obs["position"] = position
        # Before the first reset (the observation spec) there is no task yet; the map's shape is fixed.
        treasure = self._task if self._task.size else np.zeros(2)
        obs["treasure_map"] = treasure_map(position, treasure)
        return obs


class MountainTreasureBatch(MujocoBatch):
    """`num_envs` copies of `MountainTreasure`; the positions are computed here, the MuJoCo rows only
    hold them (nothing is simulated)."""

    def __init__(self, num_envs: int, seed: SeedLike = None, *, num_threads: int = 0, **task_kwargs):
        tasks = [MountainTreasure(random=s, **task_kwargs) for s in spawn_seeds(seed, num_envs)]
        super().__init__(tasks, mujoco.MjModel.from_xml_string(MODEL_XML), num_threads)
        self.sparse, self.rewards = tasks[0].sparse, tasks[0].rewards
        self._support = tasks[0].prior.support()
        self._map = np.zeros((num_envs, 2))  # the `treasure_map` observation, computed with the step

    def _transition(self, action: np.ndarray) -> np.ndarray:
        # The task's functions, each distance computed once (the step dominates this batch's time); the
        # action is already clipped, so this is `walk`.
        position = np.clip(self._qpos[:, :2] + STEP_SIZE * action, -ARENA, ARENA)
        self._qpos[:] = position
        to_top, to_treasure = _distance(position, 0.0), _distance(position, self._task)
        reward = _sparse_reward(to_top, to_treasure, self.rewards) if self.sparse else -to_treasure
        self._map = np.where((to_top < TOP_RADIUS)[:, None], self._task, 0.0)
        if self._belief is not None:
            self._belief = _belief_update(
                self._belief, self._support, position, to_top, reward, self._map, self.rewards, self.sparse
            )
        return reward

    def _reset_mdp(self) -> None:
        self._qpos[:] = START
        self._qvel[:] = 0.0
        self._map = treasure_map(self._qpos[:, :2], self._task)

    def _mdp_observation(self) -> dict[str, np.ndarray]:
        return {"position": self._qpos[:, :2].copy(), "treasure_map": self._map.copy()}

    def _load_extra_state(self, state: dict) -> None:
        self._map = treasure_map(self._qpos[:, :2], self._task)


def treasure_metrics(observations: dict[str, np.ndarray], rewards: np.ndarray, tasks: np.ndarray, **_) -> dict:
    """Deployed-exploration metrics of M deployments, one value each: `reached_top` (the map was read),
    `first_top_step` (1-based BAMDP step, NaN if never), `treasure_reached` (ever within 0.1 of it),
    `steps_to_treasure_after_top` (steps from the first map reading to the first treasure step after it,
    NaN if either never happens)."""
    position = observations["position"]  # (T, M, 2)
    top = on_top(position)
    at_treasure = _distance(position, np.asarray(tasks)[None]) <= TREASURE_RADIUS
    reached_top, found = top.any(axis=0), at_treasure.any(axis=0)
    first_top = np.where(reached_top, top.argmax(axis=0) + 1.0, np.nan)
    after = np.full(position.shape[1], np.nan)
    for m in np.flatnonzero(reached_top):
        later = np.flatnonzero(at_treasure[int(first_top[m]) :, m])
        if later.size:
            after[m] = later[0] + 1.0
    return {
        "reached_top": reached_top.astype(float),
        "first_top_step": first_top,
        "treasure_reached": found.astype(float),
        "steps_to_treasure_after_top": after,
    }


def reads_the_map(final: dict) -> bool:
    """Success: in at least 90 % of deployments the agent read the map and reached the treasure."""
    return final.get("reached_top", 0.0) >= 0.9 and final.get("treasure_reached", 0.0) >= 0.9


def draw_scene(ax, task: np.ndarray, num_goals: int | None = None) -> None:
    """The mountain's contours, the circle, the candidates of a finite prior, the treasure and the start."""
    from matplotlib.patches import Circle

    for radius in np.linspace(MOUNTAIN_RADIUS, TOP_RADIUS, 5):
        ax.add_patch(Circle((0, 0), radius, color="saddlebrown", alpha=0.12))
    ax.add_patch(Circle((0, 0), TREASURE_DISTANCE, fill=False, linestyle="--", color="0.5"))
    support = TreasurePrior(num_goals=num_goals).support()
    for candidate in () if support is None else support:
        ax.add_patch(Circle(candidate, TREASURE_RADIUS, color="0.6", alpha=0.5))
    ax.add_patch(Circle(task[:2], TREASURE_RADIUS, color="goldenrod"))
    ax.plot(*START, "s", color="0.3", markersize=5)


def _register(name: str, *, sparse: bool, num_goals: int | None, reference_task: str | None = None) -> None:
    def factory(
        seed: SeedLike = None,
        *,
        num_goals: int | None = num_goals,
        treasure: np.ndarray | None = None,
        treasure_reward: float = TREASURE_REWARD,
        step_penalty: float = STEP_PENALTY,
        mountain_height: float = MOUNTAIN_HEIGHT,
        episodes_per_task: int = 1,
        episode_length: int = EPISODE_LENGTH,
        privileged: bool = False,
    ) -> control.Environment:
        task = MountainTreasure(
            sparse=sparse,
            rewards=TreasureRewards(treasure_reward, step_penalty, mountain_height),
            num_goals=num_goals,
            treasure=treasure,
            episode_length=episode_length,
            episodes_per_task=episodes_per_task,
            privileged=privileged,
            random=seed,
        )
        return control.Environment(Physics.from_xml_string(MODEL_XML), task, n_sub_steps=1)

    def batch_factory(
        num_envs: int,
        seed: SeedLike = None,
        *,
        num_threads: int = 0,
        num_goals: int | None = num_goals,
        treasure_reward: float = TREASURE_REWARD,
        step_penalty: float = STEP_PENALTY,
        mountain_height: float = MOUNTAIN_HEIGHT,
        episodes_per_task: int = 1,
        episode_length: int = EPISODE_LENGTH,
        **kwargs,
    ) -> MountainTreasureBatch:
        return MountainTreasureBatch(
            num_envs,
            seed,
            num_threads=num_threads,
            sparse=sparse,
            rewards=TreasureRewards(treasure_reward, step_penalty, mountain_height),
            num_goals=num_goals,
            episodes_per_task=episodes_per_task,
            episode_length=episode_length,
            **kwargs,
        )

    factory.__name__ = factory.__qualname__ = name
    factory.__doc__ = f"`{name}`: Mountain Treasure (see suite.mountain_treasure)."
    register(
        name,
        batch=batch_factory,
        metrics=treasure_metrics,
        position_keys=("position",),
        reference_task=reference_task,
        success=reads_the_map if sparse else None,
        top_down=TopDownView(
            "position", (-ARENA, ARENA, -ARENA, ARENA), functools.partial(draw_scene, num_goals=num_goals)
        ),
    )(factory)


_register("mountain_treasure_sparse", sparse=True, num_goals=None, reference_task="mountain_treasure")
_register("mountain_treasure", sparse=False, num_goals=None)
_register(
    f"mountain_treasure_k{DEFAULT_GOALS}_sparse",
    sparse=True,
    num_goals=DEFAULT_GOALS,
    reference_task=f"mountain_treasure_k{DEFAULT_GOALS}",
)
_register(f"mountain_treasure_k{DEFAULT_GOALS}", sparse=False, num_goals=DEFAULT_GOALS)
