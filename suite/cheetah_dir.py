"""Cheetah-direction meta-task: run forward or backward, rewarded only outside a zone around the start.

Task prior: direction d in {-1 (backward), +1 (forward)}, 50/50.
Reward per control step (0.05 s): `d * vx - 0.05 * |a|^2` once the torso is at least `zone_radius`
(5 m) from where the MDP episode started, `-0.05 * |a|^2` inside the zone; `vx` is the torso's
x-displacement over the step divided by the step's duration, `a` the action clipped to [-1, 1].
Exact belief [P(backward), P(forward)]: [0.5, 0.5] until the first step that ends outside the zone
(whose reward reveals d), one-hot on d afterwards for the rest of the BAMDP episode.
"""

from __future__ import annotations

import functools

import numpy as np
from dm_control.rl import control

from hyperstate.suite._cheetah import (  # noqa: F401  (constants re-exported: the cheetah-direction task's numbers)
    CONTROL_TIMESTEP,
    COVERAGE,
    CTRL_COST_WEIGHT,
    EPISODE_LENGTH,
    N_SUB_STEPS,
    PHYSICS_TIMESTEP,
    SETTLE_STEPS,
    ZONE_RADIUS,
    CheetahZoneBatch,
    CheetahZoneTask,
    Physics,
    environment,
    position_axis,
)
from hyperstate.suite._registry import register
from hyperstate.suite._seeding import SeedLike

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


def direction_reward_and_belief(
    task: np.ndarray, vx: np.ndarray | float, outside: np.ndarray | bool, belief: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """One step's velocity reward and exact belief after it, for one task (`task` (1,), scalars) or a batch
    (`task` (N, 1), (N,) arrays): `d · vx` outside the zone and 0 inside, and the belief one-hot on d once
    outside, unchanged inside. The dm_control task and the fast batch both call this."""
    task, outside = np.asarray(task, dtype=np.float64), np.asarray(outside, dtype=bool)
    reward = np.where(outside, task[..., 0] * vx, 0.0)
    return reward, np.where(outside[..., None], one_hot_direction(task), belief)


class CheetahDirection(CheetahZoneTask):
    """A meta-task where the cheetah must find out which way to run; see the module docstring."""

    def __init__(self, *, direction: float | None = None, **kwargs):
        super().__init__(DirectionPrior(), task=direction, **kwargs)

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

    def caption(self) -> str:
        return "task: run forward ->" if self.direction > 0 else "task: run backward <-"

    def zone_reward(self, vx: float, outside: bool) -> float:
        reward, self._belief = direction_reward_and_belief(self._task, vx, outside, self._belief)
        return float(reward)


def bayes_optimal_estimate(reference_returns: np.ndarray, zone_radius: float = ZONE_RADIUS) -> float:
    """Estimated Bayes-optimal online return, from the task-aware reference's returns R per deployment.

    A Bayes-optimal agent exits the zone on one side; half the time that side is wrong, and it turns at
    once and crosses back, 2 × zone_radius metres, during which it earns nothing. At the reference's
    pace each metre is worth 1 / CONTROL_TIMESTEP reward (reward = velocity per step), so the detour costs
    min(R, 2 · zone_radius / CONTROL_TIMESTEP) of a deployment's return R. Turning around is taken as
    free, so this is an optimistic (upper) estimate: the mean over deployments of R − ½ · detour.
    """
    r = np.asarray(reference_returns, dtype=float)
    detour = np.minimum(np.maximum(r, 0.0), 2.0 * zone_radius / CONTROL_TIMESTEP)
    return float(np.mean(r - 0.5 * detour))


class CheetahDirectionBatch(CheetahZoneBatch):
    """`num_envs` copies of `CheetahDirection` on one `mujoco.batch.Batch`, reset together."""

    def __init__(self, num_envs: int, seed: SeedLike = None, *, num_threads: int = 0, **task_kwargs):
        super().__init__(num_envs, seed, lambda s: CheetahDirection(random=s, **task_kwargs), num_threads=num_threads)

    def zone_reward(self, vx: np.ndarray, outside: np.ndarray) -> np.ndarray:
        reward, self._belief[:] = direction_reward_and_belief(self._task, vx, outside, self._belief)
        return reward


def zone_exploration_metrics(
    observations: dict[str, np.ndarray],
    rewards: np.ndarray,
    tasks: np.ndarray,
    zone_radius: float = ZONE_RADIUS,
    **_: object,
) -> dict[str, np.ndarray]:
    """Deployed-exploration metrics of M deployments, one value per deployment (NaN: does not apply).

    `observations` are the observations each step ended in ((T, M, ...) arrays), `rewards` (T, M), `tasks`
    the true directions (M, 1). Per deployment:
    - `left_zone`: ever |x - x0| >= zone; `first_exit_step`: 1-based BAMDP step of the first exit (NaN if
      never);
    - `correct_direction`: left, and the last MDP episode ends beyond the zone on the rewarded side;
      `stuck`: left, and the last MDP episode ends back inside the zone (the paper's Figure 3 failure);
    - `distance_correct`: direction * final x-displacement;
    - `wrong_first_exit`: the first exit was on the unrewarded side (NaN if it never left);
    - `turned_around`: of the deployments whose first exit was wrong, whether the last MDP episode ends
      beyond the zone on the rewarded side (NaN for the others): the Bayes-optimal turn;
    - `return_forward`, `return_backward`: the deployment's return, on forward / backward tasks only;
    - `return_wrong_first`: the return of deployments whose first exit was wrong (does the turn pay?).
    """
    x = observations["x_displacement"][..., 0]
    direction = np.asarray(tasks)[:, 0]
    returns = np.asarray(rewards).sum(axis=0)
    outside = np.abs(x) >= zone_radius
    left = outside.any(axis=0)
    first_index = outside.argmax(axis=0)
    first = np.where(left, first_index + 1.0, np.nan)
    exit_side = np.sign(x[first_index, np.arange(x.shape[1])])
    wrong_first = left & (exit_side != np.sign(direction))
    final = x[-1]
    correct = left & (direction * final >= zone_radius)
    return {
        "left_zone": left.astype(float),
        "first_exit_step": first,
        "correct_direction": correct.astype(float),
        "stuck": (left & (np.abs(final) < zone_radius)).astype(float),
        "distance_correct": direction * final,
        "wrong_first_exit": np.where(left, wrong_first.astype(float), np.nan),
        "turned_around": np.where(wrong_first, correct.astype(float), np.nan),
        "return_forward": np.where(direction > 0, returns, np.nan),
        "return_backward": np.where(direction < 0, returns, np.nan),
        "return_wrong_first": np.where(wrong_first, returns, np.nan),
    }


def turn_pays(final: dict) -> bool:
    """A seed solved the sparse task: it ends beyond the zone on the rewarded side in ≥ 90 % of deployments,
    and the deployments whose first exit was on the wrong side earn on average (the turn-around pays). A
    seed without wrong-first deployments has nothing to turn from and counts on `correct_direction` alone."""
    wrong_first = final.get("return_wrong_first")
    return final.get("correct_direction", 0.0) >= 0.9 and (wrong_first is None or wrong_first > 0)


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
        task = CheetahDirection(
            zone_radius=zone_radius,
            ctrl_cost_weight=ctrl_cost_weight,
            direction=direction,
            episode_length=episode_length,
            episodes_per_task=episodes_per_task,
            privileged=privileged,
            random=seed,
        )
        return environment(task)

    def batch_factory(num_envs: int, seed: SeedLike = None, *, zone_radius: float = zone_radius, **kwargs):
        return CheetahDirectionBatch(num_envs, seed, zone_radius=zone_radius, **kwargs)

    factory.__name__ = factory.__qualname__ = name
    factory.__doc__ = f"`{name}`: cheetah-direction meta-task, zone radius {zone_radius} m (see suite.cheetah_dir)."
    metrics = functools.partial(zone_exploration_metrics, zone_radius=zone_radius)
    # The sparse task's task-aware reference learns on the dense task (same observations and prior).
    reference = "cheetah_dir" if zone_radius > 0 else None
    register(
        name,
        batch=batch_factory,
        metrics=metrics,
        position_keys=("x_displacement",),
        reference_task=reference,
        position_axis=position_axis(zone_radius),
        coverage=COVERAGE,
        bayes_estimate=functools.partial(bayes_optimal_estimate, zone_radius=zone_radius),
        success=turn_pays if zone_radius > 0 else None,
    )(factory)


_register("cheetah_dir_sparse", ZONE_RADIUS)
_register("cheetah_dir", 0.0)
