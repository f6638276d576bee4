"""hyperstate.suite: sparse meta-RL tasks in the dm_control suite style.

    env = suite.load("cheetah_dir_sparse", seed=0)            # a dm_control control.Environment
    vec = suite.batch("cheetah_dir_sparse", num_envs=16, seed=0)  # N copies, raw MuJoCo, NumPy in/out

Register your own meta-task from your own module with `@suite.register("name")`.
"""

import ctypes.util
import os
import sys


def _default_gl_backend() -> None:
    """dm_control reads MUJOCO_GL when first imported; unset, it tries GLFW first, which on a machine
    without a display warns about DISPLAY before falling back. Where nothing was chosen and there is no
    display, choose the headless backend it would fall back to (EGL, else OSMesa, else none)."""
    if "MUJOCO_GL" in os.environ or "dm_control" in sys.modules or sys.platform != "linux":
        return
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return
    for backend, library in (("egl", "EGL"), ("osmesa", "OSMesa")):
        if ctypes.util.find_library(library):
            os.environ["MUJOCO_GL"] = backend
            return
    os.environ["MUJOCO_GL"] = "disable"


_default_gl_backend()

from hyperstate.suite import cheetah_dir, cheetah_vel, mountain_treasure, point_robot, quadruped_goal, rooms  # noqa: F401  (register the built-in tasks)
from hyperstate.suite._batch import BatchEnv, BatchStep, LoopBatch
from hyperstate.suite._registry import (
    TASKS,
    Coverage,
    PositionAxis,
    TopDownView,
    batch,
    bayes_estimate,
    coverage,
    exploration_metrics,
    list_tasks,
    load,
    position_axis,
    position_keys,
    reference_task,
    register,
    success,
    task_prior,
    top_down,
    unregister,
)
from hyperstate.suite._seeding import as_generator, spawn_seeds
from hyperstate.suite.base import MetaTask, TaskPrior

__all__ = [
    "TASKS",
    "BatchEnv",
    "BatchStep",
    "Coverage",
    "LoopBatch",
    "MetaTask",
    "PositionAxis",
    "TaskPrior",
    "TopDownView",
    "as_generator",
    "batch",
    "bayes_estimate",
    "success",
    "coverage",
    "exploration_metrics",
    "list_tasks",
    "load",
    "position_axis",
    "position_keys",
    "reference_task",
    "register",
    "spawn_seeds",
    "task_prior",
    "top_down",
    "unregister",
]
