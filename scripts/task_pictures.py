"""Draws the pictures of docs/tasks.md: each sparse task with a scripted deployment on it.

    .venv/bin/python scripts/task_pictures.py [--out docs/figures]

Point robot tasks: top-down, the goal prior, and a scripted explorer that visits the candidate goals in
turn (the true goal starred) until it is rewarded, then stays. cheetah_vel_sparse: the reward per step
against velocity for three targets, zero inside the zone. quadruped_goal_sparse: the goal prior top-down.
mountain_treasure_sparse: the scripted climber beside the circle walker on one task; rooms_sparse: the
scripted corner explorer on one task; both drawn over the scene the task declares (`suite.top_down`).
Every reward drawn is the task's own, read from a rollout of `suite.load` where there is one.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from hyperstate import suite  # noqa: E402
from hyperstate.suite import scripted  # noqa: E402


def explore(name: str, seed: int = 3, **kwargs) -> tuple[list[np.ndarray], np.ndarray, list[float], np.ndarray]:
    """Positions per MDP episode, the candidate goals, the rewards, the true goal: a P-controller visiting
    the candidates in turn, the rewarded one kept for the rest of the BAMDP episode."""
    env = suite.load(name, seed=seed, privileged=True, **kwargs)
    step = env.reset()
    goal = np.asarray(step.observation["task"], float)
    count = kwargs.get("num_goals", 4)
    angles = np.linspace(0.0, np.pi, count)
    candidates = np.stack([np.cos(angles), np.sin(angles)], 1)
    paths, path, rewards, target, found = [], [], [], 0, None
    while not step.last():
        position = np.asarray(step.observation["position"], float)
        aim = candidates[found if found is not None else target]
        if found is None and np.linalg.norm(position - aim) < 0.1:
            target = min(target + 1, count - 1)
        step = env.step(np.clip(5.0 * (aim - position), -1, 1))
        rewards.append(float(step.reward))
        if step.reward > 0 and found is None:
            found = int(np.argmin(np.linalg.norm(candidates - step.observation["position"], axis=1)))
        if path and step.observation["inner_episode"][0] != len(paths):
            paths.append(np.array(path))
            path = []
        path.append(np.asarray(step.observation["position"], float))
    paths.append(np.array(path))
    return paths, candidates, rewards, goal


def point_picture(name: str, out: Path, **kwargs) -> Path:
    paths, candidates, rewards, goal = explore(name, **kwargs)
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    arc = np.linspace(0, np.pi, 100)
    ax.plot(np.cos(arc), np.sin(arc), color="0.7", linewidth=1, label="goal prior (half circle)")
    for c in candidates:
        ax.add_patch(plt.Circle(c, 0.2, color="0.85", zorder=0))
    ax.plot(*goal, marker="*", markersize=14, color="tab:red", linestyle="none", label="the task's goal")
    for i, path in enumerate(paths):
        ax.plot(path[:, 0], path[:, 1], label=f"MDP episode {i + 1}")
    ax.set_xlim(-1.5, 1.5)
    ax.set_ylim(-0.3, 1.4)
    ax.set_aspect("equal")
    ax.set_title(f"{name}: scripted explorer, return {sum(rewards):.0f}")
    ax.legend(fontsize=7, loc="lower center", ncol=2)
    fig.tight_layout()
    path = out / f"task_{name}.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def cheetah_vel_picture(out: Path) -> Path:
    velocity = np.linspace(-1, 4, 200)
    fig, ax = plt.subplots(figsize=(5.5, 3.2))
    for target in (0.5, 1.5, 2.5):
        ax.plot(velocity, np.maximum(0.0, 1.0 - np.abs(velocity - target)), label=f"target {target} m/s")
    ax.set_xlabel("forward velocity (m/s)")
    ax.set_ylabel("reward per step (outside the zone)")
    ax.set_title("cheetah_vel_sparse: 0 inside the 5 m zone, minus the control cost")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = out / "task_cheetah_vel_sparse.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def quadruped_picture(out: Path) -> Path:
    fig, ax = plt.subplots(figsize=(4.2, 4.2))
    circle = np.linspace(0, 2 * np.pi, 200)
    ax.plot(2 * np.cos(circle), 2 * np.sin(circle), color="0.6", label="goal prior (radius 2 m)")
    env = suite.load("quadruped_goal_sparse", seed=0, privileged=True)
    goal = np.asarray(env.reset().observation["task"], float)[:2]
    ax.add_patch(plt.Circle(goal, 0.5, color="tab:red", alpha=0.3, label="rewarded region of one task"))
    ax.plot(0, 0, marker="o", color="k", linestyle="none", label="start")
    ax.set_aspect("equal")
    ax.set_xlim(-2.8, 2.8)
    ax.set_ylim(-2.8, 2.8)
    ax.set_title("quadruped_goal_sparse")
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    path = out / "task_quadruped_goal_sparse.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def top_down_picture(name: str, strategies: dict, out: Path, task: np.ndarray, size: tuple[float, float]) -> Path:
    """One panel per scripted strategy: its path over the task's scene, titled with its return."""
    view = suite.top_down(name)
    fig, axes = plt.subplots(len(strategies), 1, figsize=size, squeeze=False)
    for ax, (label, strategy) in zip(axes[:, 0], strategies.items(), strict=True):
        env = suite.load(name, seed=0, **{"treasure" if name.startswith("mountain") else "goals": task})
        rewards, observations = scripted.rollout(env, strategy)
        view.draw_scene(ax, task)
        xy = observations[view.key]
        ax.plot(xy[:, 0], xy[:, 1], "-", color="tab:blue", linewidth=1.5)
        ax.plot(*xy[-1], "x", color="tab:blue", markersize=8)
        ax.set_xlim(*view.extent[:2])
        ax.set_ylim(*view.extent[2:])
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{label}: return {rewards.sum():.0f}", fontsize=9)
    fig.suptitle(name, fontsize=10)
    fig.tight_layout()
    path = out / f"task_{name}.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> list[Path]:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    written = [
        point_picture("point_treasure_sparse", args.out),
        point_picture("point_robot_sparse", args.out, num_goals=5),
        cheetah_vel_picture(args.out),
        quadruped_picture(args.out),
        top_down_picture(
            "mountain_treasure_sparse",
            {"climb, read the map, walk to it": scripted.MountainClimber(), "walk the circle": scripted.CircleWalker()},
            args.out,
            np.array([np.cos(2.2), np.sin(2.2)]),
            (4.0, 7.6),
        ),
        top_down_picture(
            "rooms_sparse",
            {"try the corners stage by stage": scripted.RoomsExplorer()},
            args.out,
            suite.rooms.task_support()[20],
            (8.0, 2.4),
        ),
    ]
    print(*written, sep="\n")
    return written


if __name__ == "__main__":
    main()
