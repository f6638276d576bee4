"""The scripted strategies' returns that docs/tasks.md quotes as each task's scripted bracket.

    .venv/bin/python scripts/scripted_bracket.py [--out bench/results/scripted_bracket.json]

mountain_treasure_sparse: `MountainClimber` and `CircleWalker` on 64 evenly spaced treasures;
mountain_treasure_k8_sparse: the same on its prior's 8 treasures.
rooms_sparse: `RoomsExplorer` on each of the 48 tasks.
point_treasure_sparse: `PointExplorer` over the 4 candidates, `PointExplorer` of the first candidate
alone (one guess, kept: what an agent that does not explore earns) and `PointGoalSeeker` (task-aware), on
each of the 4 tasks. point_robot_sparse: `ArcSweeper` and `PointGoalSeeker` on 64 evenly spaced goals.
Deterministic (dm_control environments, seed 0).
Prints the JSON it writes.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import numpy as np  # noqa: E402

from hyperstate import suite  # noqa: E402
from hyperstate.suite import point_robot, rooms, scripted  # noqa: E402


def summary(returns: list[float]) -> dict:
    return {"mean": round(float(np.mean(returns)), 1), "min": round(min(returns), 1), "max": round(max(returns), 1)}


def mountain(angles: int = 64) -> dict:
    out = {}
    for name, strategy in (("MountainClimber", scripted.MountainClimber()), ("CircleWalker", scripted.CircleWalker())):
        returns = []
        for angle in np.linspace(0, 2 * np.pi, angles, endpoint=False):
            env = suite.load("mountain_treasure_sparse", seed=0, treasure=[np.cos(angle), np.sin(angle)])
            returns.append(float(scripted.rollout(env, strategy)[0].sum()))
        out[name] = {"treasures": angles, **summary(returns)}
    return out


def rooms_explorer() -> dict:
    returns, all_three = [], 0
    for goals in rooms.task_support():
        env = suite.load("rooms_sparse", seed=0, goals=goals)
        rewards, obs = scripted.rollout(env, scripted.RoomsExplorer())
        metrics = rooms.rooms_metrics(
            {"position": obs["position"][:, None], "inner_episode": obs["inner_episode"][:, None]},
            rewards[:, None],
            goals[None],
        )
        returns.append(float(rewards.sum()))
        all_three += int(metrics["goals_reached"][0] == 3)
    return {"RoomsExplorer": {"tasks": len(returns), "all_three_goals": all_three, **summary(returns)}}


def point_tasks(angles: int = 64) -> dict:
    candidates = point_robot.HalfCircleGoalPrior(num_goals=point_robot.TREASURE_GOALS).support()
    treasure = {
        "PointExplorer": scripted.PointExplorer(candidates),
        "one_guess": scripted.PointExplorer(candidates[:1]),
        "PointGoalSeeker": scripted.PointGoalSeeker(),
    }
    sweep_goals = point_robot.GOAL_DISTANCE * np.stack(
        [np.cos(np.linspace(0, np.pi, angles)), np.sin(np.linspace(0, np.pi, angles))], 1
    )
    robot = {"ArcSweeper": scripted.ArcSweeper(), "PointGoalSeeker": scripted.PointGoalSeeker()}
    out = {}
    for task, goals, strategies in (
        ("point_treasure_sparse", candidates, treasure),
        ("point_robot_sparse", sweep_goals, robot),
    ):
        out[task] = {}
        for name, strategy in strategies.items():
            returns = []
            for goal in goals:
                env = suite.load(task, seed=0, goal=goal, privileged=True)
                returns.append(float(scripted.rollout(env, strategy)[0].sum()))
            out[task][name] = {"goals": len(goals), **summary(returns)}
    return out


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("bench/results/scripted_bracket.json"))
    args = parser.parse_args(argv)
    result = {
        "mountain_treasure_sparse": mountain(),
        "mountain_treasure_k8_sparse": mountain(angles=8),
        "rooms_sparse": rooms_explorer(),
        **point_tasks(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
