"""Per-run turn-around table of a cheetah-direction grid, as markdown rows (research/turnaround/notebook.md).

    .venv/bin/python research/turnaround/turnaround_summary.py runs/fig2_20m [MORE_OUTS ...] [--json OUT.json] \
        [--plot OUT.png]

For every finished cell: the final online return, returns on forward / backward tasks, the share of
deployments whose first exit was on the wrong side, the share of those that ended beyond the zone on the
right side (`turned_around`), their mean return, correct direction, stuck, the stochastic policy's return
where recorded, the curve every 2M frames, and each deployment's final x; and two numbers for the
direction asymmetry (research/turnaround/notebook.md): the share of deployments whose first exit was forward, and the
mean speed of the way back on wrong-first deployments (m/s towards the rewarded side, from the furthest
point on the wrong side to the end of the episode); and the share of deployments that end with the
cheetah on its back (`flipped`). Computed from each cell's `deployment.npz` with the
task's own metrics (`suite.exploration_metrics`), so older grids work too. `--plot` draws every run's
learning curve, one panel per agent and one line per seed (a mean over seeds would hide that a preset
learns the turn in one seed and not in another).
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np

from hyperstate import suite
from hyperstate.suite.cheetah_dir import CONTROL_TIMESTEP

ROOT_PITCH = 1  # column of the root's pitch (rooty) in the cheetah's `position` observation (qpos without x)


def exits_and_way_back(x: np.ndarray, directions: np.ndarray, wrong_first_exit: np.ndarray) -> tuple[float, float]:
    """(share of deployments whose first exit from the zone was forward, mean speed in m/s of the way back
    on deployments whose first exit was on the wrong side; NaN where none), from (T, N) x-displacements,
    (N,) task directions (±1) and the task's own per-deployment `wrong_first_exit` metric (NaN: never left)."""
    left = ~np.isnan(wrong_first_exit)
    wrong = left & (wrong_first_exit == 1.0)
    forward = np.where(wrong, directions < 0, directions > 0)  # a wrong first exit is against the task
    speeds = []
    for i in np.flatnonzero(wrong):
        turn = int(np.argmax(-directions[i] * x[:, i]))  # the furthest point on the wrong side
        steps = x.shape[0] - 1 - turn
        if steps > 0:
            speeds.append(directions[i] * (x[-1, i] - x[turn, i]) / (steps * CONTROL_TIMESTEP))
    forward_first = float(np.mean(forward[left])) if left.any() else float("nan")
    return forward_first, float(np.mean(speeds)) if speeds else float("nan")


def upside_down(pitch: np.ndarray) -> np.ndarray:
    """Whether the torso is on its back, from the root's pitch angle(s) in radians (an unlimited hinge:
    any multiple of 2π may have been added)."""
    return np.cos(pitch) < 0


def cell_rows(out: Path) -> list[dict]:
    rows = []
    for cell in sorted((out / "cells").iterdir()):
        record_path, npz = cell / "record.json", cell / "deployment.npz"
        if not record_path.exists() or not npz.exists():
            continue
        record = json.loads(record_path.read_text())
        if not record.get("complete"):
            continue
        data = np.load(npz)
        metrics = suite.exploration_metrics(record["task"])(
            {"x_displacement": data["obs_x_displacement"]}, data["rewards"], data["tasks"]
        )
        with warnings.catch_warnings():  # a metric that applies to no deployment is NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            means = {k: float(np.nanmean(v)) for k, v in metrics.items()}
        forward_first, way_back = exits_and_way_back(
            data["obs_x_displacement"][..., 0], data["tasks"][:, 0], metrics["wrong_first_exit"]
        )
        flipped = upside_down(data["obs_position"][-1, :, ROOT_PITCH])
        rows.append(
            {
                "agent": record["agent"],
                "seed": record["seed"],
                "online_return": record["final"]["online_return"],
                "stochastic_return": record["final"].get("stochastic", {}).get("online_return"),
                **means,
                "forward_first_exit": forward_first,
                "way_back_speed": way_back,
                "flipped_at_end": float(flipped.mean()),
                "curve": [p["online_return"] for p in record["curve"]],
                "curve_frames": [p["frames"] for p in record["curve"]],
                "final_x": data["obs_x_displacement"][-1, :, 0].tolist(),
                "tasks": data["tasks"][:, 0].tolist(),
            }
        )
    return rows


def markdown(rows: list[dict]) -> str:
    def f(v, spec=".0f"):
        return "—" if v is None or (isinstance(v, float) and np.isnan(v)) else format(v, spec)

    lines = [
        "| run | online return | R forward | R backward | wrong first | turned | R wrong-first | correct dir. | stuck "
        "| stochastic | first exit forward | way back m/s | flipped | curve every 2M |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        curve = ", ".join(f(v) for v in r["curve"][1::2])
        lines.append(
            f"| `{r['agent']}` s{r['seed']} | {f(r['online_return'])} | {f(r['return_forward'])} | "
            f"{f(r['return_backward'])} | {f(r['wrong_first_exit'], '.2f')} | {f(r['turned_around'], '.2f')} | "
            f"{f(r['return_wrong_first'])} | {f(r['correct_direction'], '.2f')} | {f(r['stuck'], '.2f')} | "
            f"{f(r['stochastic_return'])} | {f(r['forward_first_exit'], '.2f')} | {f(r['way_back_speed'], '.1f')} | "
            f"{f(r['flipped_at_end'], '.2f')} | "
            f"{curve} |"
        )
    return "\n".join(lines)


def rename_agents(rows: list[dict], pairs: list[str]) -> list[dict]:
    """Rows with agents renamed by "OLD=NEW" pairs, all at once (so two names can swap)."""
    names = dict(pair.split("=", 1) for pair in pairs)
    return [{**row, "agent": names.get(row["agent"], row["agent"])} for row in rows]


def plot_curves(rows: list[dict], path: Path) -> None:
    """Online return against frames for every run: a panel per agent, a line per seed, the final
    deployment's return as a dot at the budget."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    agents = list(dict.fromkeys(r["agent"] for r in rows))
    fig, axes = plt.subplots(1, len(agents), figsize=(4.2 * len(agents), 3.6), sharey=True, squeeze=False)
    for ax, agent in zip(axes[0], agents, strict=True):
        for r in sorted((r for r in rows if r["agent"] == agent), key=lambda r: r["seed"]):
            frames = np.asarray(r["curve_frames"]) / 1e6
            (line,) = ax.plot(frames, r["curve"], label=f"seed {r['seed']}: {r['online_return']:.0f}")
            ax.plot(frames[-1:], [r["online_return"]], "o", color=line.get_color())
        ax.axhline(0, color="0.6", linewidth=0.8)
        ax.set_title(agent)
        ax.set_xlabel("frames (millions)")
        ax.legend(fontsize=8, title="final online return", title_fontsize=8)
    axes[0][0].set_ylabel("online return at deployment")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("outs", type=Path, nargs="+", help="results folders of evaluation/run.py")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--plot", type=Path, default=None, help="PNG of every run's learning curve")
    parser.add_argument(
        "--rename",
        nargs="+",
        default=[],
        metavar="OLD=NEW",
        help="agent names as they should read (a grid older than a preset's renaming; applied at once, so "
        "two names can swap)",
    )
    args = parser.parse_args()
    rows = rename_agents([row for out in args.outs for row in cell_rows(out)], args.rename)
    print(markdown(rows))
    for r in rows:
        moves = " ".join(f"{t:+.0f}:{x:+.0f}" for t, x in zip(r["tasks"], r["final_x"], strict=True))
        print(f"{r['agent']} s{r['seed']} final x per task (direction:x): {moves}")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    if args.plot:
        plot_curves(rows, args.plot)


if __name__ == "__main__":
    main()
