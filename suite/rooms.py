"""Rooms: three goals in sequence in three rooms, the second found only where the first points.

A point mass (the point robot's: two motors against viscous damping, up to 0.1 m per control step of
0.05 s) moves in a MuJoCo maze: three rooms of 3 × 3 cells in a row, each cell `CELL` (0.2 m) square,
joined by corridors one cell wide and three long; walls are geoms it collides with. Every MDP episode
starts at rest in the middle room's centre and lasts 100 control steps.
Task prior (48 tasks, uniform): goal 1 is a corner cell of the middle room; goal 2 a corner cell of the
side room on goal 1's side (left of the centre: the left room); goal 3 a middle-room corner other than
goal 1. The task parameters are the three goals' cell centres (x1, y1, x2, y2, x3, y3) in metres.
Reward per control step, by the cell the step ends in (the reference's order): 0.5 in goal 1's cell;
else 5 in goal 2's once goal 1 was reached in this MDP episode; else 50 in goal 3's once goal 2 was;
else −0.05. A goal pays on every step spent in it.
Exact belief: over the 48 tasks, a candidate is kept while it would have paid exactly the rewards seen,
so visits without reward rule candidates out and each stage's reward reveals that goal.

This is the HyperX reference's grid world `RoomNavi` made continuous. The grid's agent moves one cell
per step for 50 steps and is paid 1, 10, 100 and −0.1 per step; here a cell takes two control steps at
full speed, so the episode is 100 steps and every reward is halved: a strategy earns about what it
earns on the grid. Where it differs: the point can move diagonally and carries momentum (it accelerates
with a 0.2 s time constant), cells are square regions of a plane, and walls are soft contacts. The
structure is the reference's: a small reward first, then larger ones that need the first's information.
"""

from __future__ import annotations

import collections
import itertools

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
EPISODE_LENGTH = 100  # control steps per MDP episode: the reference's 50 grid steps, two per cell
CELL = 0.2  # side of a cell (m)
ROOM_CELLS = 3  # a room is ROOM_CELLS × ROOM_CELLS cells
CORRIDOR_CELLS = 3
GOAL_REWARDS = (0.5, 5.0, 50.0)  # the reference's 1, 10, 100 per grid step, halved
STEP_PENALTY = 0.05  # the reference's 0.1, halved
HALF = ROOM_CELLS // 2  # cells from a room's centre to its border cells
SIDE_CENTRE = ROOM_CELLS + CORRIDOR_CELLS  # cells from the middle room's centre to a side room's (6)
HALF_WIDTH = (SIDE_CENTRE + HALF + 0.5) * CELL  # the maze spans ±HALF_WIDTH in x (1.5 m)
HALF_HEIGHT = (HALF + 0.5) * CELL  # and ±HALF_HEIGHT in y (0.3 m)
WALL = 0.05  # thickness of the outer walls (m)
ROBOT_RADIUS = 0.05


def _corners(centre: int) -> list[tuple[int, int]]:
    return [(centre + dx, dy) for dx in (-HALF, HALF) for dy in (HALF, -HALF)]


MIDDLE_CORNERS = _corners(0)
LEFT_CORNERS = _corners(-SIDE_CENTRE)
RIGHT_CORNERS = _corners(SIDE_CENTRE)


def _walls_xml() -> str:
    """Outer walls around the maze, and the blocks beside each corridor."""
    walls = []
    for name, x, y, sx, sy in (
        ("north", 0.0, HALF_HEIGHT + WALL, HALF_WIDTH + 2 * WALL, WALL),
        ("south", 0.0, -HALF_HEIGHT - WALL, HALF_WIDTH + 2 * WALL, WALL),
        ("west", -HALF_WIDTH - WALL, 0.0, WALL, HALF_HEIGHT),
        ("east", HALF_WIDTH + WALL, 0.0, WALL, HALF_HEIGHT),
    ):
        walls.append((name, x, y, sx, sy))
    # Beside each corridor, a block fills the cells above and below it: x from the middle room's border to
    # the side room's (0.3 to 0.9 m), y from the corridor's edge to the outer wall (0.1 to 0.3 m).
    inner, outer = (HALF + 0.5) * CELL, (HALF + 0.5 + CORRIDOR_CELLS) * CELL
    block = ((inner + outer) / 2, (HALF_HEIGHT + CELL / 2) / 2, (outer - inner) / 2, (HALF_HEIGHT - CELL / 2) / 2)
    for side, sign_x in (("west", -1), ("east", 1)):
        for row, sign_y in (("north", 1), ("south", -1)):
            walls.append((f"{side}_corridor_{row}", sign_x * block[0], sign_y * block[1], block[2], block[3]))
    return "\n".join(
        f'    <geom name="{n}" type="box" class="wall" pos="{x:.4f} {y:.4f} 0.05" size="{sx:.4f} {sy:.4f} 0.05"/>'
        for n, x, y, sx, sy in walls
    )


MODEL_XML = f"""
<mujoco model="rooms">
  <option timestep="{PHYSICS_TIMESTEP}"/>
  <visual><global offwidth="960" offheight="320"/></visual>
  <default>
    <joint type="slide" damping="5" limited="false"/>
    <motor gear="10" ctrlrange="-1 1" ctrllimited="true"/>
    <geom contype="0" conaffinity="0"/>
    <default class="wall">
      <geom contype="1" conaffinity="1" rgba=".35 .35 .4 1"/>
    </default>
  </default>
  <worldbody>
    <light pos="0 0 4" dir="0 0 -1"/>
    <camera name="top" pos="0 0 2.4" xyaxes="1 0 0 0 1 0"/>
    <geom name="floor" type="plane" size="{HALF_WIDTH + 0.2} {HALF_HEIGHT + 0.2} 0.1" rgba=".85 .85 .85 1"/>
{_walls_xml()}
    <body name="robot" pos="0 0 0.05">
      <joint name="x" axis="1 0 0"/>
      <joint name="y" axis="0 1 0"/>
      <geom name="robot" type="sphere" size="{ROBOT_RADIUS}" mass="1" contype="1" conaffinity="1" rgba=".8 .3 .3 1"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="x" joint="x"/>
    <motor name="y" joint="y"/>
  </actuator>
</mujoco>
"""


def task_support() -> np.ndarray:
    """The 48 tasks (48, 6): goal cells' centres (m), in the order goal 1, goal 2, goal 3."""
    rows = []
    for first in MIDDLE_CORNERS:
        side = LEFT_CORNERS if first[0] < 0 else RIGHT_CORNERS
        for second, third in itertools.product(side, MIDDLE_CORNERS):
            if third != first:
                rows.append([*first, *second, *third])
    return CELL * np.array(rows, dtype=np.float64)


class RoomsPrior:
    """Uniform over the 48 tasks of `task_support()`."""

    def __init__(self):
        self._support = task_support()

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return self._support[rng.integers(len(self._support))].copy()

    def support(self) -> np.ndarray:
        return self._support.copy()

    def probabilities(self) -> np.ndarray:
        return np.full(len(self._support), 1.0 / len(self._support))


def cell_of(position: np.ndarray) -> np.ndarray:
    """Integer cell coordinates (..., 2) of positions (..., 2) in metres (cell (0, 0) is the centre)."""
    return np.round(np.asarray(position) / CELL).astype(np.int64)


CODE_BASE = 64  # cells are coded as one integer, i · CODE_BASE + j, for fast comparisons


def cell_code(position: np.ndarray) -> np.ndarray:
    """One integer per position (...,), equal exactly when two positions lie in the same cell."""
    cell = cell_of(position)
    return cell[..., 0] * CODE_BASE + cell[..., 1]


def goal_codes(goals: np.ndarray) -> np.ndarray:
    """The cell codes (..., 3) of tasks (..., 6): goal 1, goal 2, goal 3."""
    goals = np.asarray(goals)
    return cell_code(goals.reshape(*goals.shape[:-1], 3, 2))


def stage_reward(
    code: np.ndarray, goals: np.ndarray, reached: np.ndarray, rewards=GOAL_REWARDS, penalty: float = STEP_PENALTY
) -> tuple[np.ndarray, np.ndarray]:
    """Reward of ending a step in the cell coded `code` (...) when the goals' cells are coded `goals`
    (..., 3) (`goal_codes`) and the stages reached so far in this MDP episode are `reached` (..., 3)
    bools; broadcasts. Returns the reward (...) and the stages reached after the step."""
    on = np.asarray(goals) == np.asarray(code)[..., None]
    first = on[..., 0]
    second = ~first & reached[..., 0] & on[..., 1]
    third = ~first & ~second & reached[..., 1] & on[..., 2]
    reward = np.where(first, rewards[0], np.where(second, rewards[1], np.where(third, rewards[2], -penalty)))
    return reward, reached | np.stack([first, second, third], axis=-1)


def belief_update(
    belief: np.ndarray, support_codes: np.ndarray, code: np.ndarray, reached: np.ndarray, reward: np.ndarray
) -> np.ndarray:
    """Exact Bayes update of beliefs (N, 48) over the tasks coded `support_codes` (48, 3) after steps
    ending in cells coded `code` (N,) with `reward` (N,), `reached` (N, 3) the stages reached before the
    step. Every candidate still possible has reached the same stages as the true task (a stage is
    reached exactly when its reward was seen), and rewards are deterministic given the task: the
    likelihood is 1 where a candidate would have paid exactly this reward and 0 elsewhere."""
    predicted, _ = stage_reward(code[:, None], support_codes[None], reached[:, None, :])  # (N, 48)
    posterior = belief * (np.abs(predicted - reward[:, None]) <= 1e-9)
    return posterior / posterior.sum(axis=1, keepdims=True)


class Physics(MjPhysics):
    """Physics of the rooms' point mass."""

    def robot_position(self) -> np.ndarray:
        return self.data.qpos[:2].copy()


class Rooms(MetaTask):
    """The Rooms meta-task; see the module docstring."""

    def __init__(self, *, goals: np.ndarray | None = None, **kwargs):
        self._support = task_support()  # set first: force_task checks tasks against it
        self._support_codes = goal_codes(self._support)
        super().__init__(RoomsPrior(), task=goals, **kwargs)
        self._reached = np.zeros(3, bool)
        self._action_spec = None

    def force_task(self, task) -> None:
        if task is not None:
            task = np.asarray(task, dtype=np.float64)
            if task.shape != (6,) or not np.any(np.all(np.isclose(self._support, task), axis=1)):
                raise ValueError(
                    f"goals must be one of the prior's 48 tasks (see suite.rooms.task_support()), got {task.tolist()}"
                )
        super().force_task(task)

    @property
    def reached(self) -> np.ndarray:
        """Privileged: which goals were reached in this MDP episode."""
        return self._reached.copy()

    video_camera = "top"

    def prior_belief(self) -> np.ndarray:
        return self._prior.probabilities()

    def caption(self) -> str:
        cells = cell_of(self._task.reshape(3, 2))
        return "task: goals " + " → ".join(f"({x:+d}, {y:+d})" for x, y in cells)

    def markers(self, physics: Physics) -> list[Marker]:
        """The three goals' cells, light to dark green in their order."""
        size = (CELL / 2, CELL / 2, 0.001)
        return [
            Marker("box", (*self._task[2 * k : 2 * k + 2], 0.001), size, (0.2, 0.4 + 0.2 * k, 0.2, 0.6))
            for k in range(3)
        ]

    def initialize_mdp_episode(self, physics: Physics) -> None:
        physics.data.qpos[:] = 0.0
        physics.data.qvel[:] = 0.0
        self._reached = np.zeros(3, bool)

    def action_spec(self, physics: Physics):
        if self._action_spec is None:
            self._action_spec = suite_base.Task.action_spec(self, physics)
        return self._action_spec

    def before_step(self, action, physics: Physics) -> None:
        spec = self.action_spec(physics)
        physics.set_control(np.clip(check_action(action, spec), spec.minimum, spec.maximum))

    def transition_reward(self, physics: Physics) -> float:
        code = cell_code(physics.robot_position())
        reward, reached = stage_reward(code, goal_codes(self._task), self._reached)
        belief = belief_update(self._belief[None], self._support_codes, code[None], self._reached[None], reward[None])
        self._belief, self._reached = belief[0], reached
        return float(reward)

    def mdp_observation(self, physics: Physics) -> collections.OrderedDict:
        obs = collections.OrderedDict()
        obs["position"] = physics.data.qpos[:2].copy()
        obs["velocity"] = physics.data.qvel[:2].copy()
        return obs


class RoomsBatch(MujocoBatch):
    """`num_envs` copies of `Rooms` on one `mujoco.batch.Batch`, reset together."""

    def __init__(self, num_envs: int, seed: SeedLike = None, *, num_threads: int = 0, **task_kwargs):
        tasks = [Rooms(random=s, **task_kwargs) for s in spawn_seeds(seed, num_envs)]
        super().__init__(tasks, mujoco.MjModel.from_xml_string(MODEL_XML), num_threads)
        self._support_codes = goal_codes(task_support())
        self._reached = np.zeros((num_envs, 3), bool)
        self._goal_codes = np.zeros((num_envs, 3), np.int64)

    def _reset_mdp(self) -> None:
        self._sim.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)  # qpos0 = 0 (the middle room's centre), at rest
        self._reached = np.zeros((self.num_envs, 3), bool)
        self._goal_codes = goal_codes(self._task)  # the task is fixed until the next reset

    def _transition(self, action: np.ndarray) -> np.ndarray:
        self._ctrl[:] = action
        self._step_physics(N_SUB_STEPS)
        code = cell_code(self._qpos[:, :2])
        reward, reached = stage_reward(code, self._goal_codes, self._reached)
        self._belief = belief_update(self._belief, self._support_codes, code, self._reached, reward)
        self._reached = reached
        return reward

    def _mdp_observation(self) -> dict[str, np.ndarray]:
        return {"position": self._qpos[:, :2].copy(), "velocity": self._qvel[:, :2].copy()}

    def _extra_state(self) -> dict:
        return {"reached": self._reached.copy()}

    def _load_extra_state(self, state: dict) -> None:
        self._reached = state["reached"].copy()
        self._goal_codes = goal_codes(self._task)


def rooms_metrics(observations: dict[str, np.ndarray], rewards: np.ndarray, tasks: np.ndarray, **_) -> dict:
    """Deployed-exploration metrics of M deployments, one value each: `goals_reached` (0–3, the most
    stages reached in one MDP episode) and `first_goal_<k>_step` (1-based BAMDP step at which goal k was
    first reached in order, NaN if never), recomputed from the positions."""
    codes = cell_code(observations["position"])  # (T, M)
    episode = observations["inner_episode"][..., 0]  # (T, M): the MDP episode each step ended in
    goals = goal_codes(tasks)  # (M, 3)
    steps, m = codes.shape
    reached = np.zeros((m, 3), bool)
    first = np.full((m, 3), np.nan)
    most = np.zeros(m)
    for t in range(steps):
        _, reached = stage_reward(codes[t], goals, reached)
        first = np.where(reached & np.isnan(first), t + 1.0, first)
        most = np.maximum(most, reached.sum(axis=1))
        if t + 1 < steps:  # the step ending an MDP episode shows the next one's first observation
            new_episode = episode[t + 1] != episode[t]
            reached[new_episode] = False
    return {"goals_reached": most, **{f"first_goal_{k + 1}_step": first[:, k] for k in range(3)}}


def all_three_goals(final: dict) -> bool:
    """Success: `goals_reached` averages at least 2.9, i.e. at least 90 % of deployments reach all three."""
    return final.get("goals_reached", 0.0) >= 2.9


def draw_scene(ax, task: np.ndarray) -> None:
    """Walls, the candidate corners, and the task's three goals numbered in order."""
    from matplotlib.patches import Rectangle

    model = mujoco.MjModel.from_xml_string(MODEL_XML)
    for g in range(model.ngeom):
        if model.geom_contype[g] and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
            (x, y, _), (sx, sy, _) = model.geom_pos[g], model.geom_size[g]
            ax.add_patch(Rectangle((x - sx, y - sy), 2 * sx, 2 * sy, color="0.35"))
    for corner in (*MIDDLE_CORNERS, *LEFT_CORNERS, *RIGHT_CORNERS):
        x, y = CELL * np.array(corner)
        ax.add_patch(Rectangle((x - CELL / 2, y - CELL / 2), CELL, CELL, fill=False, color="0.6", linewidth=0.5))
    for k in range(3):
        x, y = task[2 * k : 2 * k + 2]
        ax.add_patch(Rectangle((x - CELL / 2, y - CELL / 2), CELL, CELL, color="tab:green", alpha=0.3 + 0.2 * k))
        ax.text(x, y, str(k + 1), ha="center", va="center", fontsize=8)


def rooms_batch(
    num_envs: int,
    seed: SeedLike = None,
    *,
    num_threads: int = 0,
    episodes_per_task: int = 1,
    episode_length: int = EPISODE_LENGTH,
    **kwargs,
) -> RoomsBatch:
    """The fast batch of `rooms_sparse` (same keyword arguments)."""
    return RoomsBatch(
        num_envs,
        seed,
        num_threads=num_threads,
        episodes_per_task=episodes_per_task,
        episode_length=episode_length,
        **kwargs,
    )


EXTENT = (-HALF_WIDTH - 2 * WALL, HALF_WIDTH + 2 * WALL, -HALF_HEIGHT - 2 * WALL, HALF_HEIGHT + 2 * WALL)


@register(
    "rooms_sparse",
    batch=rooms_batch,
    metrics=rooms_metrics,
    position_keys=("position",),
    success=all_three_goals,
    top_down=TopDownView("position", EXTENT, draw_scene),
)
def rooms_sparse(
    seed: SeedLike = None,
    *,
    goals: np.ndarray | None = None,
    episodes_per_task: int = 1,
    episode_length: int = EPISODE_LENGTH,
    privileged: bool = False,
) -> control.Environment:
    """`rooms_sparse`: three goals in sequence in three rooms (see suite.rooms)."""
    task = Rooms(
        goals=goals,
        episode_length=episode_length,
        episodes_per_task=episodes_per_task,
        privileged=privileged,
        random=seed,
    )
    return control.Environment(Physics.from_xml_string(MODEL_XML), task, n_sub_steps=N_SUB_STEPS)
