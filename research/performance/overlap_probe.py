"""Does overlapping physics with policy inference pay on this machine? A probe before building it.

    python research/performance/overlap_probe.py [--num-envs 16] [--steps 1500] [--repeats 3] [--out FILE]

Sequential: every step, one torch inference over all envs (actor and critic MLPs and a GRU cell, the
sizes of the presets' per-step work), then `mujoco.batch.Batch.step` of all envs on 2 physics threads.
Overlapped (EnvPool's async idea inside one process): two half batches of 1 physics thread each; half
A's inference, then half A's physics in a worker thread (MuJoCo releases the GIL) while the main thread
runs half B's inference and physics. Cheetah, 5 substeps per control step. Writes frames/s of both.
Run it with nothing else on the CPU.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import mujoco  # noqa: E402
import mujoco.batch  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from dm_control.suite import cheetah  # noqa: E402

SUBSTEPS = 5
OBS_DIM, HIDDEN, BELIEF = 20, 128, 64


def _mlp(out: int) -> torch.nn.Sequential:
    return torch.nn.Sequential(
        torch.nn.Linear(OBS_DIM, HIDDEN), torch.nn.Tanh(), torch.nn.Linear(HIDDEN, HIDDEN), torch.nn.Tanh(),
        torch.nn.Linear(HIDDEN, out),
    )  # fmt: skip


class Probe:
    def __init__(self, num_envs: int):
        torch.set_num_threads(1)
        self.n = num_envs
        model = mujoco.MjModel.from_xml_string(*cheetah.get_model_and_assets())
        self.actor, self.critic, self.encoder = _mlp(6), _mlp(1), torch.nn.GRUCell(OBS_DIM, BELIEF)
        self.full = mujoco.batch.Batch(model, nsim=num_envs, nthread=2)
        self.halves = [mujoco.batch.Batch(model, nsim=num_envs // 2, nthread=1) for _ in range(2)]
        self.pool = ThreadPoolExecutor(1)

    def _infer(self, sim: mujoco.batch.Batch, hidden: torch.Tensor) -> torch.Tensor:
        obs = np.concatenate([sim.bind("qpos"), sim.bind("qvel"), sim.bind("qvel")[:, :3]], axis=1)[:, :OBS_DIM]
        with torch.inference_mode():
            x = torch.as_tensor(obs, dtype=torch.float32)
            action, _ = self.actor(x), self.critic(x)
            hidden = self.encoder(x, hidden)
        sim.bind("ctrl")[:] = action.numpy().astype(np.float64).clip(-1, 1)
        return hidden

    def sequential(self, steps: int) -> float:
        hidden = torch.zeros(self.n, BELIEF)
        start = time.perf_counter()
        for _ in range(steps):
            hidden = self._infer(self.full, hidden)
            self.full.step(nstep=SUBSTEPS)
        return self.n * steps / (time.perf_counter() - start)

    def overlapped(self, steps: int) -> float:
        a, b = self.halves
        ha, hb = torch.zeros(self.n // 2, BELIEF), torch.zeros(self.n // 2, BELIEF)
        start = time.perf_counter()
        for _ in range(steps):
            ha = self._infer(a, ha)
            pending = self.pool.submit(a.step, None, SUBSTEPS)
            hb = self._infer(b, hb)
            b.step(nstep=SUBSTEPS)
            pending.result()
        return self.n * steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path("bench/results/overlap_probe.json"))
    args = parser.parse_args()
    probe = Probe(args.num_envs)
    runs = [(probe.sequential(args.steps), probe.overlapped(args.steps)) for _ in range(args.repeats)]
    result = {
        "num_envs": args.num_envs,
        "steps": args.steps,
        "cpus": os.cpu_count(),
        "sequential_frames_per_second": [round(s) for s, _ in runs],
        "overlapped_frames_per_second": [round(o) for _, o in runs],
        "overlapped_over_sequential": round(float(np.median([o / s for s, o in runs])), 3),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
