"""hyperstate.suite: sparse meta-RL tasks in the dm_control suite style.

    env = suite.load("cheetah_dir_sparse", seed=0)            # a dm_control control.Environment
    vec = suite.batch("cheetah_dir_sparse", num_envs=16, seed=0)  # N copies, raw MuJoCo, NumPy in/out

Register your own meta-task from your own module with `@suite.register("name")`.
"""

from suite import cheetah_dir, cheetah_vel, point_robot, quadruped_goal  # noqa: F401  (register the built-in tasks)
from suite._batch import BatchEnv, BatchStep, LoopBatch
from suite._registry import (
    TASKS,
    batch,
    exploration_metrics,
    list_tasks,
    load,
    position_keys,
    reference_task,
    register,
    task_prior,
    unregister,
)
from suite._seeding import as_generator, spawn_seeds
from suite.base import MetaTask, TaskPrior

__all__ = [
    "TASKS",
    "BatchEnv",
    "BatchStep",
    "LoopBatch",
    "MetaTask",
    "TaskPrior",
    "as_generator",
    "batch",
    "exploration_metrics",
    "list_tasks",
    "load",
    "position_keys",
    "reference_task",
    "register",
    "spawn_seeds",
    "task_prior",
    "unregister",
]
