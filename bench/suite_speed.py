"""Control steps per second of cheetah_dir_sparse: dm_control env, raw MuJoCo, and suite.batch.

    python bench/suite_speed.py [--steps 20000] [--num-envs 16 64] [--out bench/results/suite_speed.json]

Every measurement steps the same model with 5 physics substeps per control step and random actions.
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
from dm_control.suite import cheetah  # noqa: E402

from hyperstate import suite  # noqa: E402
from hyperstate.suite.cheetah_dir import N_SUB_STEPS  # noqa: E402


def dm_control_env(steps: int) -> float:
    env = suite.load("cheetah_dir_sparse", seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, 6))
    env.reset()
    start = time.perf_counter()
    for a in actions:
        if env.step(a).last():
            env.reset()
    return steps / (time.perf_counter() - start)


def raw_mj_step(steps: int) -> float:
    model = mujoco.MjModel.from_xml_string(*cheetah.get_model_and_assets())
    data = mujoco.MjData(model)
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, 6))
    start = time.perf_counter()
    for a in actions:
        data.ctrl[:] = a
        mujoco.mj_step(model, data, N_SUB_STEPS)
    return steps / (time.perf_counter() - start)


def raw_batch(steps: int, num_envs: int, threads: int) -> float:
    model = mujoco.MjModel.from_xml_string(*cheetah.get_model_and_assets())
    sim = mujoco.batch.Batch(model, nsim=num_envs, nthread=threads)
    ctrl = sim.bind("ctrl")
    rng = np.random.default_rng(0)
    n_calls = max(1, steps // num_envs)
    start = time.perf_counter()
    for _ in range(n_calls):
        ctrl[:] = rng.uniform(-1, 1, (num_envs, 6))
        sim.step(nstep=N_SUB_STEPS)
    return n_calls * num_envs / (time.perf_counter() - start)


def suite_batch(steps: int, num_envs: int, threads: int) -> float:
    vec = suite.batch("cheetah_dir_sparse", num_envs, seed=0, num_threads=threads)
    rng = np.random.default_rng(0)
    n_calls = max(1, steps // num_envs)
    vec.reset()
    start = time.perf_counter()
    for _ in range(n_calls):
        vec.step(rng.uniform(-1, 1, (num_envs, 6)))
    return n_calls * num_envs / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=20_000, help="control steps per measurement")
    parser.add_argument("--num-envs", type=int, nargs="+", default=[16, 64])
    parser.add_argument("--out", type=Path, default=Path("bench/results/suite_speed.json"))
    args = parser.parse_args()
    threads = sorted({1, os.cpu_count() or 1})
    result: dict = {
        "task": "cheetah_dir_sparse",
        "substeps_per_control_step": N_SUB_STEPS,
        "control_steps_per_measurement": args.steps,
        "machine": {"cpus": os.cpu_count(), "processor": platform.processor(), "python": platform.python_version()},
        "mujoco": mujoco.__version__,
        "steps_per_second": {
            "dm_control_env": round(dm_control_env(args.steps)),
            "raw_mj_step_loop": round(raw_mj_step(args.steps)),
        },
    }
    for n in args.num_envs:
        for t in threads:
            result["steps_per_second"][f"raw_mujoco_batch_n{n}_threads{t}"] = round(raw_batch(args.steps, n, t))
            result["steps_per_second"][f"suite_batch_n{n}_threads{t}"] = round(suite_batch(args.steps, n, t))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
