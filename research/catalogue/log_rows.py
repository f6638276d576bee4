"""The calibration log's rows (research/catalogue/README.md) from results folders: per cell, its training
wall time, the online return at every evaluation point and the final deployment's task metrics.

    .venv/bin/python research/catalogue/log_rows.py docs/results/calibration/rooms_sparse [more folders]

Reads each folder's cells/*/record.json, finished or not (an unfinished cell is marked), and prints one
Markdown table per folder.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def cell_rows(folder: Path) -> list[dict]:
    """One row per cell of `folder`: agent, seed, frames, wall seconds, curve, final metrics, complete."""
    records = sorted(folder.glob("cells/*/record.json"))
    if not records:
        raise SystemExit(f"{folder}: no cells/*/record.json (not an evaluation/run.py results folder)")
    rows = []
    for path in records:
        record = json.loads(path.read_text())
        curve = record.get("curve") or []
        final = record.get("final") or {}
        rows.append(
            {
                "agent": record["agent"],
                "seed": record["seed"],
                "frames": curve[-1]["frames"] if curve else 0,
                "wall_seconds": curve[-1]["wall_seconds"] if curve else 0.0,
                "curve": [point["online_return"] for point in curve],
                "final": {name: final.get(name) for name in final.get("exploration_metric_names", [])},
                "complete": bool(record.get("complete")),
            }
        )
    return rows


def _number(value: float | None) -> str:
    return "—" if value is None else f"{value:,.2f}".rstrip("0").rstrip(".")


def markdown(rows: list[dict]) -> str:
    lines = ["| agent | seed | wall | curve | final |", "|---|---|---|---|---|"]
    for row in rows:
        curve = ", ".join(f"{v:,.1f}" for v in row["curve"][:-1])
        last = f"**{row['curve'][-1]:,.1f}**" if row["curve"] else ""
        final = ", ".join(f"`{name}` {_number(value)}" for name, value in row["final"].items())
        state = "" if row["complete"] else f" (unfinished, {row['frames']:,} frames)"
        lines.append(
            f"| {row['agent']} | {row['seed']} | {row['wall_seconds']:,.0f} s{state} | "
            f"{curve}{', ' if curve else ''}{last} | {final} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folders", type=Path, nargs="+", help="evaluation/run.py results folders")
    args = parser.parse_args(argv)
    for folder in args.folders:
        print(f"{folder}\n\n{markdown(cell_rows(folder))}\n")


if __name__ == "__main__":
    main()
