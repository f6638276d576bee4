"""Learning per second, not frames per second: the online-return curve against training time per num_envs.

    python bench/learning_speed.py --preset oracle --task cheetah_dir --num-envs 16 32 64 \
        --frames 1000000 --eval-every 100000 --seeds 0 1 [--out FILE]

More envs per iteration raise frames/s (per-step overhead is shared by more envs) but give fewer, larger
PPO updates per frame; which `num_envs` learns fastest *per second* is an empirical question. For each
num_envs and seed this trains the preset, deploys it every `--eval-every` frames on `--eval-tasks`
held-out tasks (deterministic actions, as the harness does; deployment time is not counted as training
time) and records (frames, training seconds, online return). The summary per num_envs: training
frames/s, the final online return, the online return after the training time the fastest setting
needed for the whole budget (linear interpolation of each seed's curve; the fair comparison at equal
wall-clock), and the training seconds to first reach half of the best final return of any setting.
Run it with nothing else on the CPU; compare only settings measured in one run.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import numpy as np  # noqa: E402

from hyperstate import agents  # noqa: E402
from hyperstate.evaluation.deploy import deploy, evaluation_tasks  # noqa: E402


def learning_curve(preset: str, task: str, num_envs: int, frames: int, eval_every: int, eval_tasks: int, seed: int):
    """[(frames, training seconds, online return)] of one run: a point at the first iteration at or past
    each multiple of `eval_every`, and at the end."""
    agent = agents.make(preset, **{"ppo.num_envs": num_envs, "torch_threads": 1})
    tasks = evaluation_tasks(task, eval_tasks)
    curve: list[tuple[int, float, float]] = []
    evaluating = [0.0]  # seconds spent deploying, taken off the training time
    started = time.perf_counter()

    def on_iteration(log: dict) -> None:
        done = log["frames"] >= frames
        if log["frames"] // eval_every > (curve[-1][0] // eval_every if curve else 0) or done:
            t0 = time.perf_counter()
            training_seconds = t0 - started - evaluating[0]
            online = float(deploy(agent, task, tasks).rewards.sum(0).mean())
            evaluating[0] += time.perf_counter() - t0
            curve.append((log["frames"], training_seconds, online))

    agent.train(task, frames=frames, seed=seed, progress=False, on_iteration=on_iteration)
    return curve


def return_at(curve, seconds: float) -> float:
    """Online return after `seconds` of training, interpolated along the curve (0 frames: no point)."""
    times = [t for _, t, _ in curve]
    returns = [r for _, _, r in curve]
    return float(np.interp(seconds, times, returns))


def seconds_to_reach(curve, target: float) -> float | None:
    """Training seconds at the first evaluation point with an online return ≥ `target` (None: never)."""
    return next((t for _, t, r in curve if r >= target), None)


def summarise(curves: dict[int, list[list[tuple[int, float, float]]]]) -> dict:
    """Per num_envs: frames/s, final return, return at the fastest setting's total time, time to half the
    best final return; every number a mean over seeds (None where a seed never got there)."""
    budget = min(np.mean([c[-1][1] for c in runs]) for runs in curves.values())
    best_final = max(np.mean([c[-1][2] for c in runs]) for runs in curves.values())
    summary = {}
    for n, runs in curves.items():
        reach = [seconds_to_reach(c, 0.5 * best_final) for c in runs]
        summary[str(n)] = {
            "train_frames_per_second": float(np.mean([c[-1][0] / c[-1][1] for c in runs])),
            "final_online_return": float(np.mean([c[-1][2] for c in runs])),
            "online_return_at_equal_time": float(np.mean([return_at(c, budget) for c in runs])),
            "seconds_to_half_best_final": None if None in reach else float(np.mean(reach)),
        }
    return {"equal_time_seconds": float(budget), "half_best_final": float(0.5 * best_final), "by_num_envs": summary}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--preset", default="oracle")
    parser.add_argument("--task", default="cheetah_dir")
    parser.add_argument("--num-envs", type=int, nargs="+", default=[16, 32, 64])
    parser.add_argument("--frames", type=int, default=1_000_000)
    parser.add_argument("--eval-every", type=int, default=100_000)
    parser.add_argument("--eval-tasks", type=int, default=20)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--out", type=Path, default=None, help="default bench/results/learning_speed_<preset>.json")
    args = parser.parse_args()
    curves: dict[int, list] = {}
    for n in args.num_envs:
        for s in args.seeds:
            curve = learning_curve(args.preset, args.task, n, args.frames, args.eval_every, args.eval_tasks, s)
            curves.setdefault(n, []).append(curve)
            frames, seconds, online = curve[-1]
            print(
                f"num_envs {n} seed {s}: {frames:,} frames in {seconds:.0f} s, online return {online:.1f}",
                flush=True,
            )
    result = {
        "preset": args.preset,
        "task": args.task,
        "frames": args.frames,
        "seeds": args.seeds,
        "curves": {str(n): runs for n, runs in curves.items()},
        **summarise(curves),
    }
    out = args.out or Path(f"bench/results/learning_speed_{args.preset}.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: v for k, v in result.items() if k != "curves"}, indent=2))


if __name__ == "__main__":
    main()
