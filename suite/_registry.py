"""The public task registry: `register`, `load`, `batch`, `list_tasks`.

A task is a factory `factory(seed=None, **kwargs) -> control.Environment`. It may come with a batched
simulator factory `batch_factory(num_envs, seed=None, num_threads=0, **kwargs) -> BatchEnv` (same kwargs); tasks
without one are batched by `LoopBatch`, which steps dm_control environments one by one.

What the evaluation harness knows of a task it learns here, from what the task declares: its
deployed-exploration metrics, its position (for state bonuses), its dense reference task, the position
axis it is drawn along (`PositionAxis`), its hyper-state coverage grid (`Coverage`) and its Bayes-optimal
return estimator. A task that declares none of these gets none of them; the harness names no task.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable
from typing import Any

import numpy as np

from hyperstate.registry import Registry
from hyperstate.suite._batch import BatchEnv, LoopBatch
from hyperstate.suite._seeding import SeedLike, spawn_seeds

Factory = Callable[..., Any]


@dataclasses.dataclass(frozen=True)
class PositionAxis:
    """A one-number position the harness draws the agent along: the behaviour plot (position against
    step of the final deployment), the bonus landscape (evaluation/diagnostics.py) and the video caption.

    `key` is the observation whose first component is the position; `label` the axis label; `symbol` and
    `unit` how captions write it (`x +3.1 m`); `region`, if given, an interval of the axis drawn with
    dashed borders and named in captions (`(inside zone)`), e.g. a sparse task's zone without reward.
    """

    key: str
    label: str
    symbol: str = "position"
    unit: str = ""
    region: tuple[float, float] | None = None
    region_name: str = "region"

    def __post_init__(self) -> None:
        if self.region is not None:
            low, high = self.region
            if not low < high:
                raise ValueError(f"PositionAxis region must be (low, high) with low < high, got {self.region}")
            object.__setattr__(self, "region", (float(low), float(high)))

    def describe(self, position: float) -> str:
        """The position in words, for a caption: `x +3.1 m (outside zone)`."""
        text = f"{self.symbol} {position:+.1f}" + (f" {self.unit}" if self.unit else "")
        if self.region is not None:
            inside = self.region[0] < position < self.region[1]
            text += f" ({'inside' if inside else 'outside'} {self.region_name})"
        return text


@dataclasses.dataclass(frozen=True)
class Coverage:
    """The hyper-state coverage grid of a task (evaluation/coverage.py): `bins` equal bins of observation
    `key`'s first component over [low, high] (positions beyond fall in the edge bins) × `belief_bins` equal
    bins of the exact belief's last component (observation `belief_key`)."""

    key: str
    low: float
    high: float
    bins: int = 40
    belief_bins: int = 3
    belief_key: str = "belief"

    def __post_init__(self) -> None:
        if not self.low < self.high or self.bins < 1 or self.belief_bins < 1:
            raise ValueError(f"Coverage needs low < high and positive bin counts, got {self}")


@dataclasses.dataclass(frozen=True)
class TopDownView:
    """A top-down view of a task on the plane, for tasks whose position is two numbers: the behaviour plot
    draws the final deployment's path in it (evaluation/report.py).

    `key` is the observation whose first two components are (x, y); `extent` the (x_min, x_max, y_min,
    y_max) drawn; `draw_scene(ax, task)`, if given, draws the task's fixed scene and the given task's
    parameters (walls, candidate goals, the true goal) into a matplotlib axes before the path is drawn.
    """

    key: str
    extent: tuple[float, float, float, float]
    draw_scene: Callable[[Any, np.ndarray], None] | None = None

    def __post_init__(self) -> None:
        x_min, x_max, y_min, y_max = (float(v) for v in self.extent)
        if not (x_min < x_max and y_min < y_max):
            raise ValueError(f"TopDownView extent must be (x_min, x_max, y_min, y_max), got {self.extent}")
        object.__setattr__(self, "extent", (x_min, x_max, y_min, y_max))
        if self.draw_scene is not None and not callable(self.draw_scene):
            raise TypeError(f"draw_scene must be callable, got {type(self.draw_scene).__name__}")


@dataclasses.dataclass(frozen=True)
class TaskEntry:
    """One registered meta-task."""

    name: str
    factory: Factory
    batch_factory: Callable[..., BatchEnv] | None = None
    metrics: Callable[..., dict] | None = None
    position_keys: tuple[str, ...] | None = None
    reference_task: str | None = None
    position_axis: PositionAxis | None = None
    coverage: Coverage | None = None
    bayes_estimate: Callable[[np.ndarray], float] | None = None
    success: Callable[[dict], bool] | None = None
    top_down: TopDownView | None = None


_REGISTRY: Registry[TaskEntry] = Registry("task", "registered tasks")

# Live, sorted view of the registered names (a list, so `name in suite.TASKS` and printing both work).
TASKS: list[str] = []


def register(
    name: str,
    *,
    batch: Callable[..., BatchEnv] | None = None,
    metrics: Callable[..., dict] | None = None,
    position_keys: tuple[str, ...] | None = None,
    reference_task: str | None = None,
    position_axis: PositionAxis | None = None,
    coverage: Coverage | None = None,
    bayes_estimate: Callable[[np.ndarray], float] | None = None,
    success: Callable[[dict], bool] | None = None,
    top_down: TopDownView | None = None,
) -> Callable[[Factory], Factory]:
    """Decorator registering `factory(seed=None, **kwargs)` under `name`.

    `batch`, if given, is a batched simulator factory `batch(num_envs, seed=None, num_threads=0, **kwargs)`
    taking the factory's keyword arguments; it must reproduce the dm_control environment exactly (see
    `suite.batch`). `metrics`, if given, computes deployed-exploration metrics
    `metrics(observations, rewards, tasks, **task_kwargs) -> {name: (M,) array}` from M deployments
    ((T, M, ...) observations each step ended in, (T, M) rewards, (M, P) true tasks).
    `position_keys`, if given, names the observations that say where the agent is (what state-based
    exploration bonuses look at by default, e.g. `("x_displacement",)`).
    `reference_task`, if given, names a registered task with the same observations, actions, task prior
    and horizon (MDP episodes per task, steps per episode) but a dense reward (e.g. `cheetah_dir` for
    `cheetah_dir_sparse`): the task-aware reference policy learns it there and is deployed on this task
    (evaluation/run.py).
    `position_axis` (a `PositionAxis`), if given, is the one-number position the harness plots the agent
    along; `coverage` (a `Coverage`), if given, the hyper-state grid whose visited fraction the grid logs;
    `bayes_estimate`, if given, maps the task-aware reference's returns per deployment to an estimate of
    the Bayes-optimal online return (`summary.csv`'s `bayes_estimate`); `success`, if given, says from a
    cell's final deployment metrics (the averaged `record["final"]` dict) whether that seed solved the task,
    so that a high mean return cannot hide seeds that did not (`summary.csv`'s `success_share`);
    `top_down` (a `TopDownView`), if given, is the plane the behaviour plot draws a two-number position in.
    """
    _REGISTRY.check_free(name)
    for value, kind, what in (
        (position_axis, PositionAxis, "position_axis"),
        (coverage, Coverage, "coverage"),
        (top_down, TopDownView, "top_down"),
    ):
        if value is not None and not isinstance(value, kind):
            raise TypeError(f"{what} must be a suite.{kind.__name__}, got {type(value).__name__}")
    for value, what in ((bayes_estimate, "bayes_estimate"), (success, "success")):
        if value is not None and not callable(value):
            raise TypeError(f"{what} must be callable, got {type(value).__name__}")
    if reference_task is not None and (not isinstance(reference_task, str) or reference_task == name):
        raise ValueError(f"reference_task must be another task's name, got {reference_task!r}")

    def decorator(factory: Factory) -> Factory:
        _REGISTRY.check_free(name)
        if "seed" not in inspect.signature(factory).parameters:
            raise TypeError(f"factory for {name!r} must accept a `seed` keyword argument")
        entry = TaskEntry(
            name,
            factory,
            batch,
            metrics,
            None if position_keys is None else tuple(position_keys),
            reference_task,
            position_axis,
            coverage,
            bayes_estimate,
            success,
            top_down,
        )
        _REGISTRY.add(name, entry, owner=factory.__module__)
        TASKS[:] = _REGISTRY.names()
        return factory

    return decorator


def unregister(name: str) -> None:
    """Removes a registered task (mainly for tests and interactive sessions)."""
    _REGISTRY.remove(name)
    TASKS[:] = _REGISTRY.names()


def exploration_metrics(name: str) -> Callable[..., dict] | None:
    """The deployed-exploration metrics function task `name` declares, or None."""
    return _lookup(name).metrics


def position_keys(name: str) -> tuple[str, ...] | None:
    """The observation keys task `name` declares as its position (for state bonuses), or None."""
    return _lookup(name).position_keys


def position_axis(name: str) -> PositionAxis | None:
    """The position axis task `name` declares for plots and captions, or None."""
    return _lookup(name).position_axis


def coverage(name: str) -> Coverage | None:
    """The hyper-state coverage grid task `name` declares, or None."""
    return _lookup(name).coverage


def bayes_estimate(name: str) -> Callable[[np.ndarray], float] | None:
    """Task `name`'s Bayes-optimal return estimator (from task-aware reference returns), or None."""
    return _lookup(name).bayes_estimate


def success(name: str) -> Callable[[dict], bool] | None:
    """Task `name`'s success criterion on a cell's final deployment metrics, or None."""
    return _lookup(name).success


def top_down(name: str) -> TopDownView | None:
    """The top-down view task `name` declares for behaviour plots, or None."""
    return _lookup(name).top_down


def reference_task(name: str) -> str | None:
    """The registered dense counterpart of task `name` (where its task-aware reference learns), or None.
    Raises ValueError where it is not registered or has another horizon than `name`."""
    reference = _lookup(name).reference_task
    if reference is None:
        return None
    if reference not in _REGISTRY:
        raise ValueError(f"task {name!r} names reference_task {reference!r}, which is not registered")
    # A reference trained over fewer MDP episodes never sees the later ones' observations (`inner_episode`)
    # and is lost in them at deployment; one over other episode lengths learns other timing.
    horizon, reference_horizon = _horizon(name), _horizon(reference)
    if horizon != reference_horizon:
        raise ValueError(
            f"task {name!r} has {_describe_horizon(horizon)} but its reference_task {reference!r} has "
            f"{_describe_horizon(reference_horizon)}: the task-aware reference must learn the same horizon"
        )
    return reference


def _horizon(name: str) -> tuple[int | None, int | None]:
    """(MDP episodes per task, steps per MDP episode) of task `name`, None where its task does not say."""
    task = load(name, seed=0).task
    return getattr(task, "episodes_per_task", None), getattr(task, "episode_length", None)


def _describe_horizon(horizon: tuple[int | None, int | None]) -> str:
    episodes, length = horizon
    return f"{episodes} MDP episode(s) of {length} steps per task"


def task_prior(name: str, **kwargs: Any):
    """The task prior of a registered task (from a throwaway instance of its environment)."""
    return load(name, seed=0, **kwargs).task.prior


def list_tasks() -> list[str]:
    """Registered task names, sorted."""
    return list(TASKS)


def _lookup(name: str) -> TaskEntry:
    return _REGISTRY.lookup(name)


def _check_kwargs(name: str, factory: Callable[..., Any], kwargs: dict[str, Any]) -> None:
    params = inspect.signature(factory).parameters
    if any(p.kind is p.VAR_KEYWORD for p in params.values()):
        return
    accepted = [p for p in params if p not in ("seed", "num_envs")]
    unknown = sorted(set(kwargs) - set(accepted))
    if unknown:
        raise TypeError(
            f"task {name!r} got unknown keyword argument(s) {', '.join(map(repr, unknown))}; "
            f"accepted: {', '.join(accepted) or 'none'}"
        )


def load(name: str, seed: SeedLike = None, **kwargs: Any):
    """Returns the dm_control environment of the registered task `name`.

    `seed` (int, `numpy.random.SeedSequence`, `numpy.random.Generator` or None) seeds every random draw
    of the task: task parameters from the prior and initial states.
    """
    entry = _lookup(name)
    _check_kwargs(name, entry.factory, kwargs)
    return entry.factory(seed=seed, **kwargs)


def batch(name: str, num_envs: int, seed: SeedLike = None, *, num_threads: int = 0, **kwargs: Any) -> BatchEnv:
    """Returns `num_envs` copies of task `name` stepped together, with auto-reset at BAMDP episode ends.

    Copy `i` draws its randomness from `suite.spawn_seeds(seed, num_envs)[i]`, so it reproduces
    `suite.load(name, seed=suite.spawn_seeds(seed, num_envs)[i], **kwargs)` step for step.
    `num_threads` is the fast batch's physics thread count (0: one per CPU); results do not depend on it.
    """
    if not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
        raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
    entry = _lookup(name)
    _check_kwargs(name, entry.factory, kwargs)
    if entry.batch_factory is not None:
        return entry.batch_factory(int(num_envs), seed=seed, num_threads=num_threads, **kwargs)
    seeds = spawn_seeds(seed, int(num_envs))
    return LoopBatch([entry.factory(seed=s, **kwargs) for s in seeds])
