"""The public task registry: `register`, `load`, `batch`, `list_tasks`.

A task is a factory `factory(seed=None, **kwargs) -> control.Environment`. It may come with a batched
simulator factory `batch_factory(num_envs, seed=None, **kwargs) -> BatchEnv` (same kwargs); tasks
without one are batched by `LoopBatch`, which steps dm_control environments one by one.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable
from typing import Any

import numpy as np

from hyperstate.suite._batch import BatchEnv, LoopBatch
from hyperstate.suite._seeding import SeedLike, spawn_seeds

Factory = Callable[..., Any]


@dataclasses.dataclass(frozen=True)
class TaskEntry:
    """One registered meta-task."""

    name: str
    factory: Factory
    batch_factory: Callable[..., BatchEnv] | None = None
    metrics: Callable[..., dict] | None = None
    position_keys: tuple[str, ...] | None = None
    reference_task: str | None = None


_REGISTRY: dict[str, TaskEntry] = {}

# Live, sorted view of the registered names (a list, so `name in suite.TASKS` and printing both work).
TASKS: list[str] = []


def register(
    name: str,
    *,
    batch: Callable[..., BatchEnv] | None = None,
    metrics: Callable[..., dict] | None = None,
    position_keys: tuple[str, ...] | None = None,
    reference_task: str | None = None,
) -> Callable[[Factory], Factory]:
    """Decorator registering `factory(seed=None, **kwargs)` under `name`.

    `batch`, if given, is a batched simulator factory `batch(num_envs, seed=None, num_threads=0, **kwargs)`
    taking the factory's keyword arguments; it must reproduce the dm_control environment exactly (see
    `suite.batch`). `metrics`, if given, computes deployed-exploration metrics
    `metrics(observations, rewards, tasks, **task_kwargs) -> {name: (M,) array}` from M deployments
    ((T, M, ...) observations each step ended in, (T, M) rewards, (M, P) true tasks).
    `position_keys`, if given, names the observations that say where the agent is (what state-based
    exploration bonuses look at by default, e.g. `("x_displacement",)`).
    `reference_task`, if given, names a registered task with the same observations, actions and task
    prior but a dense reward (e.g. `cheetah_dir` for `cheetah_dir_sparse`): the task-aware reference
    policy learns it there and is deployed on this task (evaluation/run.py).
    """
    if not isinstance(name, str) or not name:
        raise ValueError(f"task name must be a non-empty string, got {name!r}")
    if reference_task is not None and (not isinstance(reference_task, str) or reference_task == name):
        raise ValueError(f"reference_task must be another task's name, got {reference_task!r}")

    def decorator(factory: Factory) -> Factory:
        if name in _REGISTRY:
            raise ValueError(f"task {name!r} is already registered (by {_REGISTRY[name].factory.__module__})")
        if "seed" not in inspect.signature(factory).parameters:
            raise TypeError(f"factory for {name!r} must accept a `seed` keyword argument")
        _REGISTRY[name] = TaskEntry(
            name, factory, batch, metrics, None if position_keys is None else tuple(position_keys), reference_task
        )
        TASKS[:] = sorted(_REGISTRY)
        return factory

    return decorator


def unregister(name: str) -> None:
    """Removes a registered task (mainly for tests and interactive sessions)."""
    _lookup(name)
    del _REGISTRY[name]
    TASKS[:] = sorted(_REGISTRY)


def exploration_metrics(name: str) -> Callable[..., dict] | None:
    """The deployed-exploration metrics function task `name` declares, or None."""
    return _lookup(name).metrics


def position_keys(name: str) -> tuple[str, ...] | None:
    """The observation keys task `name` declares as its position (for state bonuses), or None."""
    return _lookup(name).position_keys


def reference_task(name: str) -> str | None:
    """The registered dense counterpart of task `name` (where its task-aware reference learns), or None."""
    reference = _lookup(name).reference_task
    if reference is not None and reference not in _REGISTRY:
        raise ValueError(f"task {name!r} names reference_task {reference!r}, which is not registered")
    return reference


def task_prior(name: str, **kwargs: Any):
    """The task prior of a registered task (from a throwaway instance of its environment)."""
    return load(name, seed=0, **kwargs).task.prior


def list_tasks() -> list[str]:
    """Registered task names, sorted."""
    return list(TASKS)


def _lookup(name: str) -> TaskEntry:
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; registered tasks: {', '.join(TASKS)}") from None


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
