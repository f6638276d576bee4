"""Control steps per second of every registered task: `suite.batch` against raw MuJoCo of the same model.

    python bench/suite_speed.py [--tasks NAME ...] [--num-envs 16] [--threads N] [--steps 20000]
                                [--out bench/results/suite_speed.json]

For each task, one run measures `suite.batch(task, N, num_threads=T)` and a raw `mujoco.batch.Batch`
of the task's own model (from its dm_control environment) with the same N copies, T threads and
physics substeps per control step, both driven by the same uniform random actions; the two are timed
in alternating chunks, so that a machine's drift hits both alike, and reported with their ratio (what
`suite.batch` adds: rewards, beliefs, observations, resets). A task's dm_control environment
(`suite.load`) is timed too, for scale. Only ratios measured in one run compare across machines.
Prints the JSON it writes.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import mujoco  # noqa: E402
import mujoco.batch  # noqa: E402
import numpy as np  # noqa: E402

from hyperstate import suite  # noqa: E402

CHUNKS = 3  # alternating chunks per measurement


def task_physics(task: str) -> tuple[mujoco.MjModel, int]:
    """The task's MuJoCo model and its physics substeps per control step, read from its dm_control env."""
    env = suite.load(task, seed=0)
    return env.physics.model.ptr, int(env._n_sub_steps)


def raw_batch(steps: int, num_envs: int, threads: int, task: str = "cheetah_dir_sparse") -> float:
    """Control steps per second of raw `mujoco.batch.Batch` physics of `task`'s model (random controls)."""
    calls = max(1, steps // num_envs)
    return calls * num_envs / RawBatch(task, num_envs, threads).time(calls)


class RawBatch:
    """Raw MuJoCo: the task's model on `mujoco.batch.Batch`, random controls, the task's substeps."""

    def __init__(self, task: str, num_envs: int, threads: int):
        model, self.substeps = task_physics(task)
        self.sim = mujoco.batch.Batch(model, nsim=num_envs, nthread=threads)
        self.ctrl = self.sim.bind("ctrl")
        low, high = model.actuator_ctrlrange.T
        self.rng, self.low, self.high, self.n = np.random.default_rng(0), low, high, num_envs

    def time(self, calls: int) -> float:
        """Seconds for `calls` batched control steps."""
        start = time.perf_counter()
        for _ in range(calls):
            self.ctrl[:] = self.rng.uniform(self.low, self.high, (self.n, len(self.low)))
            self.sim.step(nstep=self.substeps)
        return time.perf_counter() - start


class SuiteBatch:
    """The suite: `suite.batch(task)`, random actions."""

    def __init__(self, task: str, num_envs: int, threads: int):
        self.vec = suite.batch(task, num_envs, seed=0, num_threads=threads)
        spec = self.vec.action_spec()
        self.rng, self.low, self.high, self.n = np.random.default_rng(0), spec.minimum, spec.maximum, num_envs
        self.vec.reset()

    def time(self, calls: int) -> float:
        """Seconds for `calls` batched control steps."""
        start = time.perf_counter()
        for _ in range(calls):
            self.vec.step(self.rng.uniform(self.low, self.high, (self.n, *self.low.shape)))
        return time.perf_counter() - start


def dm_control_env(task: str, steps: int) -> float:
    env = suite.load(task, seed=0)
    spec = env.action_spec()
    actions = np.random.default_rng(0).uniform(spec.minimum, spec.maximum, (steps, *spec.shape))
    env.reset()
    start = time.perf_counter()
    for a in actions:
        if env.step(a).last():
            env.reset()
    return steps / (time.perf_counter() - start)


def measure(task: str, steps: int, num_envs: int, threads: int) -> dict:
    """One task's row: steps/s of the raw batch, the suite's batch and the dm_control env; the ratio."""
    raw, fast = RawBatch(task, num_envs, threads), SuiteBatch(task, num_envs, threads)
    calls = max(1, steps // (num_envs * CHUNKS))
    raw.time(1), fast.time(1)  # warm-up: thread pools, first allocations
    raw_seconds = fast_seconds = 0.0
    for _ in range(CHUNKS):
        raw_seconds += raw.time(calls)
        fast_seconds += fast.time(calls)
    done = calls * CHUNKS * num_envs
    return {
        "substeps_per_control_step": raw.substeps,
        "fast_batch": not isinstance(fast.vec, suite.LoopBatch),
        "raw_mujoco_batch": round(done / raw_seconds),
        "suite_batch": round(done / fast_seconds),
        "ratio": round(raw_seconds / fast_seconds, 3),
        "dm_control_env": round(dm_control_env(task, max(200, steps // 10))),
    }


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", nargs="+", default=None, help="registered tasks (default: all)")
    parser.add_argument("--steps", type=int, default=20_000, help="control steps per measurement, all copies")
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--out", type=Path, default=Path("bench/results/suite_speed.json"))
    args = parser.parse_args(argv)
    tasks = args.tasks or suite.list_tasks()
    result: dict = {
        "num_envs": args.num_envs,
        "threads": args.threads,
        "control_steps_per_measurement": args.steps,
        "machine": {"cpus": os.cpu_count(), "processor": platform.processor(), "python": platform.python_version()},
        "mujoco": mujoco.__version__,
        "tasks": {},
    }
    for task in tasks:
        result["tasks"][task] = measure(task, args.steps, args.num_envs, args.threads)
        row = result["tasks"][task]
        print(f"{task:32s} suite {row['suite_batch']:>8,}  raw {row['raw_mujoco_batch']:>8,}  ratio {row['ratio']:.2f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
