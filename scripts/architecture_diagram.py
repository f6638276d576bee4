"""Draws docs/figures/architecture.png: rollout → learn → deploy, and where each component plugs in.

    .venv/bin/python scripts/architecture_diagram.py [OUT.png]

The boxes name the modules that docs/architecture.md describes; tests/test_docs.py checks that every module
named here exists, so the picture cannot drift from the code without a failing test.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures" / "architecture.png"

# Colours: one per kind of component, as in the page's legend.
TASK, BELIEF, BONUS, PPO, HARNESS, PHASE = "#dbe9f6", "#fde2c8", "#e3f1d9", "#ece0f3", "#f4f4f4", "#ffffff"

# (x, y, width, height, title, module, colour)
BOXES = [
    (0.2, 4.9, 3.4, 1.2, "Task (BatchEnv)", "suite/ · suite.batch(name, n)", TASK),
    (0.2, 3.4, 3.4, 1.2, "Belief.update / features", "agents/beliefs/", BELIEF),
    (0.2, 1.9, 3.4, 1.2, "ActorCritic.step", "agents/ppo.py", PPO),
    (0.2, 0.4, 3.4, 1.2, "Rollout.store_step", "agents/rollout.py", PPO),
    (4.6, 4.9, 3.6, 1.2, "1 · intrinsic rewards", "Bonus.reward, .update (agents/bonuses.py)", BONUS),
    (4.6, 3.65, 3.6, 1.0, "2 · eq. (4): r + Σ β·bonus", "agents/rewards.py", BONUS),
    (4.6, 2.4, 3.6, 1.0, "3 · returns, advantages", "Rollout.compute_returns_and_advantages", PPO),
    (4.6, 1.15, 3.6, 1.0, "4 · PPO update", "agents/ppo.py", PPO),
    (4.6, 0.0, 3.6, 0.9, "5 · belief training", "Belief.train_step (agents/beliefs/)", BELIEF),
    (9.2, 4.9, 3.6, 1.2, "Grid: agents × tasks × seeds", "evaluation/run.py", HARNESS),
    (9.2, 3.4, 3.6, 1.2, "Cell: train to each point", "evaluation/cell.py (CellRun)", HARNESS),
    (9.2, 1.9, 3.6, 1.2, "Deploy on held-out tasks", "evaluation/deploy.py", HARNESS),
    (9.2, 0.4, 3.6, 1.2, "Summary, figures, report", "evaluation/report.py", HARNESS),
]
PHASES = [
    (0.0, 0.1, 3.8, 6.5, "Rollout  (Trainer.collect)"),
    (4.4, -0.3, 4.0, 6.9, "Learn  (Trainer.learn)"),
    (9.0, 0.1, 4.0, 6.5, "Deploy  (evaluation/)"),
]
PLUGS = [
    (TASK, "suite.register(name, ...)  · a task"),
    (BELIEF, "agents.register_belief  · a belief"),
    (BONUS, "agents.register_bonus  · a bonus"),
    (PPO, "agents.register_preset  · a preset"),
    (HARNESS, "evaluation.register_agent  · any agent"),
]


def box(ax, x, y, w, h, title, module, colour) -> None:
    ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.02,rounding_size=0.12", fc=colour, ec="#555", lw=1))
    ax.text(x + w / 2, y + h * 0.62, title, ha="center", va="center", fontsize=10, weight="bold")
    ax.text(x + w / 2, y + h * 0.27, module, ha="center", va="center", fontsize=8, family="monospace")


def arrow(ax, start, end, text: str = "", rad: float = 0.0) -> None:
    ax.add_patch(
        FancyArrowPatch(
            start,
            end,
            arrowstyle="-|>",
            mutation_scale=14,
            lw=1.3,
            color="#333",
            connectionstyle=f"arc3,rad={rad}",
        )
    )
    if text:
        ax.text((start[0] + end[0]) / 2, (start[1] + end[1]) / 2 + 0.12, text, ha="center", fontsize=8, style="italic")


def draw(out: Path = OUT) -> Path:
    fig, ax = plt.subplots(figsize=(13.5, 8.2))
    for x, y, w, h, title in PHASES:
        ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.02", fc=PHASE, ec="#999", ls="--"))
        ax.text(x + w / 2, y + h - 0.2, title, ha="center", fontsize=12, weight="bold")
    for spec in BOXES:
        box(ax, *spec)
    # Rollout: the loop over time steps.
    arrow(ax, (1.9, 4.9), (1.9, 4.6), "")
    arrow(ax, (1.9, 3.4), (1.9, 3.1))
    arrow(ax, (1.9, 1.9), (1.9, 1.6))
    arrow(ax, (0.3, 2.5), (0.3, 5.3), "action", rad=-0.35)
    # Learn: the five steps.
    for y0, y1 in ((4.9, 4.65), (3.65, 3.4), (2.4, 2.15), (1.15, 0.9)):
        arrow(ax, (6.4, y0), (6.4, y1))
    arrow(ax, (3.6, 1.0), (4.6, 5.3))
    ax.text(3.75, 1.35, "next iteration", fontsize=8, style="italic", rotation=72)
    arrow(ax, (4.6, 0.2), (3.6, 5.6), rad=-0.12)
    ax.text(3.95, 3.1, "rollout", fontsize=8, style="italic", rotation=62)
    # Deploy.
    arrow(ax, (8.2, 1.65), (9.2, 3.9), "agent at a point")
    for y0, y1 in ((4.9, 4.6), (3.4, 3.1), (1.9, 1.6)):
        arrow(ax, (11.0, y0), (11.0, y1))
    # Where a contributor plugs in.
    ax.text(
        0.0,
        -1.0,
        "Where your code plugs in (each a registry, hyperstate.registry.Registry):",
        fontsize=10,
        weight="bold",
    )
    for i, (colour, text) in enumerate(PLUGS):
        x, y = 0.0 + (i % 3) * 4.5, -1.6 - (i // 3) * 0.6
        ax.add_patch(FancyBboxPatch((x, y), 0.35, 0.35, boxstyle="round,pad=0.01", fc=colour, ec="#555"))
        ax.text(x + 0.5, y + 0.17, text, va="center", fontsize=9, family="monospace")
    ax.set_xlim(-0.2, 13.2)
    ax.set_ylim(-2.6, 6.8)
    ax.axis("off")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return out


def modules_named() -> list[str]:
    """The repository paths the diagram names (files and folders), for the docs test."""
    names = []
    for *_, module, _ in BOXES:
        names += [w for w in module.replace("(", " ").replace(")", " ").split() if "/" in w or w.endswith(".py")]
    return names


if __name__ == "__main__":
    print(draw(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT))
