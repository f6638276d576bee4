"""Training throughput of a preset next to raw physics, measured in one process.

    python bench/throughput.py --preset hyperx [--frames 64000] [--num-envs 16] [--out FILE]

Reports training frames/s of the full loop (rollout, bonuses, PPO, belief updates), raw physics
frames/s for the same number of control steps on `mujoco.batch.Batch` with the same number of envs and
threads, their ratio, and a breakdown of the training time: seconds per phase over the run (the
trainer's `time/<phase>` log: policy inference, physics, belief updates, rollout bookkeeping, bonuses,
reward combination + GAE, PPO epochs, belief training) and each phase's share, and the physics phase's
own frames/s (the task's env steps inside the loop, resets and reward included).
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from suite_speed import raw_batch  # noqa: E402  (bench/ is on sys.path when run as a script)

from hyperstate import agents  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--preset", default="hyperx")
    parser.add_argument("--task", default="cheetah_dir_sparse")
    parser.add_argument("--frames", type=int, default=64_000)
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--torch-threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None, help="default bench/results/throughput_<preset>.json")
    args = parser.parse_args()
    agent = agents.make(args.preset, **{"ppo.num_envs": args.num_envs, "torch_threads": args.torch_threads})
    log = agent.train(args.task, frames=args.frames, seed=0, progress=False)
    frames = log[-1]["frames"]
    train_fps = frames / log[-1]["wall_seconds"]
    collect_fps = float(np.mean([e["collect_fps"] for e in log]))
    threads = agent.config.physics_threads or os.cpu_count() or 1
    physics_fps = raw_batch(frames, args.num_envs, threads)
    result = {
        "preset": args.preset,
        "task": args.task,
        "frames": frames,
        "num_envs": args.num_envs,
        "torch_threads": torch.get_num_threads(),
        "physics_threads": threads,
        "cpus": os.cpu_count(),
        "train_frames_per_second": round(train_fps),
        "collect_frames_per_second": round(collect_fps),
        "raw_physics_frames_per_second": round(physics_fps),
        "train_over_raw_physics": round(train_fps / physics_fps, 3),
        "collect_share_of_time": round(train_fps / collect_fps, 3),
    }
    seconds = {k.removeprefix("time/"): sum(e[k] for e in log) for k in log[0] if k.startswith("time/")}
    total = log[-1]["wall_seconds"]
    result["seconds_per_phase"] = {k: round(v, 2) for k, v in seconds.items()}
    result["share_per_phase"] = {k: round(v / total, 3) for k, v in seconds.items()}
    result["share_unaccounted"] = round(1 - sum(seconds.values()) / total, 3)
    # Physics as the loop runs it: settled random starts and learned gaits
    # (research/performance/physics_state_probe.py).
    result["loop_physics_frames_per_second"] = round(frames / seconds["physics"])
    out = args.out or Path(f"bench/results/throughput_{args.preset}.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
