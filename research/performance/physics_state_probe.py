"""How much does the physics cost depend on what the cheetah does? Raw `mujoco.batch.Batch` in four regimes.

    python research/performance/physics_state_probe.py [--num-envs 16] [--episodes 4] [--out FILE]

`bench/throughput.py`'s raw-physics yardstick steps the cheetah from dm_control's default pose with
uniform random actions. Training does more per frame: every 200-step MDP episode starts from a random
pose settled for 200 physics steps (the task's reset), and a learned gait makes more contacts than
flailing. This probe times only `Batch.step` of the control steps (5 substeps each; 2 threads), in
episodes of 200 control steps, for: the default pose with uniform actions (the yardstick), a settled
random pose with uniform actions, with bang-bang actions, and with a periodic full-amplitude gait; and
the settling's time relative to the episode's steps. Medians over episodes, the regimes taking turns.
Run it with nothing else on the CPU.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import mujoco  # noqa: E402
import mujoco.batch  # noqa: E402
import numpy as np  # noqa: E402
from dm_control.suite import cheetah  # noqa: E402

SUBSTEPS, SETTLE, EPISODE = 5, 200, 200


class Regime:
    """One batch of cheetahs, a start (dm_control's default pose, or a random pose settled as the task
    resets) and an action pattern; `episode()` times one MDP episode's control steps and its settling."""

    def __init__(self, model, num_envs: int, settled: bool, policy, rng):
        self.sim = mujoco.batch.Batch(model, nsim=num_envs, nthread=2)
        self.ctrl, self.qpos = self.sim.bind("ctrl"), self.sim.bind("qpos")
        self.limited = np.flatnonzero(model.jnt_limited == 1)
        self.lower, self.upper = model.jnt_range[self.limited].T
        self.num_envs, self.settled, self.policy, self.rng = num_envs, settled, policy, rng

    def episode(self) -> tuple[float, float]:
        """(seconds of the control steps, seconds of settling)."""
        self.sim.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
        settling = stepping = 0.0
        if self.settled:
            self.qpos[:, self.limited] = self.rng.uniform(self.lower, self.upper, (self.num_envs, len(self.limited)))
            start = time.perf_counter()
            self.sim.step(nstep=SETTLE)
            settling = time.perf_counter() - start
        for t in range(EPISODE):
            self.ctrl[:] = self.policy(t, self.num_envs)
            start = time.perf_counter()
            self.sim.step(nstep=SUBSTEPS)
            stepping += time.perf_counter() - start
        return stepping, settling


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--episodes", type=int, default=12, help="episodes of each regime")
    parser.add_argument("--out", type=Path, default=Path("bench/results/physics_state.json"))
    args = parser.parse_args()
    model = mujoco.MjModel.from_xml_string(*cheetah.get_model_and_assets())
    rng = np.random.default_rng(0)
    phase = np.arange(6)
    regimes = {
        "default_pose_uniform_actions": (False, lambda t, n: rng.uniform(-1, 1, (n, 6))),
        "settled_pose_uniform_actions": (True, lambda t, n: rng.uniform(-1, 1, (n, 6))),
        "settled_pose_bang_bang_actions": (True, lambda t, n: np.sign(rng.normal(size=(n, 6)))),
        "settled_pose_periodic_gait": (True, lambda t, n: np.clip(3 * np.sin(t / 3 + phase), -1, 1)[None].repeat(n, 0)),
    }
    built = {name: Regime(model, args.num_envs, settled, policy, rng) for name, (settled, policy) in regimes.items()}
    times: dict[str, list[tuple[float, float]]] = {name: [] for name in regimes}
    for _ in range(args.episodes):  # one episode of each regime per round: the machine's drift falls on all
        for name, regime in built.items():
            times[name].append(regime.episode())
    frames = EPISODE * args.num_envs
    result: dict = {
        "num_envs": args.num_envs,
        "episodes": args.episodes,
        "control_frames_per_second_median": {
            name: round(frames / statistics.median(s for s, _ in t)) for name, t in times.items()
        },
    }
    settled = [t for name, t in times.items() if regimes[name][0]]
    result["settling_over_episode_steps_median"] = round(statistics.median(b / a for t in settled for a, b in t), 3)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
