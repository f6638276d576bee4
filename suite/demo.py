"""Demo: roll out scripted gaits on cheetah_dir_sparse and print returns and beliefs.

    python -m hyperstate.suite.demo [--seed 0] [--episodes-per-task 2]

For each true direction it runs the gait that goes the right way and the one that goes the wrong
way, through the dm_control environment, and prints the BAMDP return, the step at which the torso
first left the 5 m zone and the exact belief at the end.
"""

from __future__ import annotations

import argparse

import numpy as np

from hyperstate import suite
from hyperstate.suite.cheetah_dir import BACKWARD, FORWARD
from hyperstate.suite.scripted import gait


def rollout(direction: float, gait_direction: float, seed: int, episodes_per_task: int) -> dict:
    env = suite.load("cheetah_dir_sparse", seed=seed, direction=direction, episodes_per_task=episodes_per_task)
    policy = gait(gait_direction)
    step = env.reset()
    total, t, left_at, inner_returns = 0.0, 0, None, [0.0] * episodes_per_task
    while not step.last():
        inner = int(step.observation["inner_episode"][0])
        step = env.step(policy(t))
        t += 1
        total += step.reward
        inner_returns[inner] += step.reward
        if left_at is None and env.task.belief.max() == 1.0:
            left_at = t
    return {"return": total, "inner_returns": inner_returns, "left_zone_at": left_at, "belief": env.task.belief}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--episodes-per-task", type=int, default=2)
    args = parser.parse_args(argv)
    print(f"registered tasks: {', '.join(suite.TASKS)}")
    print(f"cheetah_dir_sparse, {args.episodes_per_task} MDP episode(s) of 200 steps per task, seed {args.seed}\n")
    name = {FORWARD: "forward", BACKWARD: "backward"}
    print(f"{'task':>9} {'gait':>9} {'return':>9} {'per episode':>22} {'left zone at':>13}  final belief")
    for direction in (FORWARD, BACKWARD):
        for gait_direction in (direction, -direction):
            r = rollout(direction, gait_direction, args.seed, args.episodes_per_task)
            per_episode = " ".join(f"{x:8.1f}" for x in r["inner_returns"])
            left = "never" if r["left_zone_at"] is None else f"step {r['left_zone_at']}"
            print(
                f"{name[direction]:>9} {name[gait_direction]:>9} {r['return']:9.1f} {per_episode:>22} "
                f"{left:>13}  {np.round(r['belief'], 2)}"
            )


if __name__ == "__main__":
    main()
