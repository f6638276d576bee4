"""The calibration log's rows (research/catalogue/README.md) from results folders: per cell, its training
wall time, the online return at every evaluation point and the final deployment's task metrics.

    .venv/bin/python research/catalogue/log_rows.py docs/results/calibration/rooms_sparse [more folders]

Reads each folder's cells/*/record.json, finished or not (an unfinished cell is marked), and prints one
Markdown table per folder; `--task` adds the task column of the point grids' table.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hyperstate.evaluation.cell import load_records, record_progress


def cell_rows(folder: Path) -> list[dict]:
    """One row per cell of `folder` (evaluation.cell.record_progress), with the final deployment's declared
    task metrics only."""
    records = load_records(folder)
    if not records:
        raise SystemExit(f"{folder}: no cells/*/record.json (not an evaluation/run.py results folder)")
    rows = []
    for record in records:
        row = record_progress(record)
        final = row["final"]
        rows.append({**row, "final": {name: final.get(name) for name in final.get("exploration_metric_names", [])}})
    return rows


def _number(value: float | None) -> str:
    return "—" if value is None else f"{value:,.2f}".rstrip("0").rstrip(".")


def markdown(rows: list[dict], task: bool = False) -> str:
    lines = ["| task " * task + "| agent | seed | wall | curve | final |", "|---" * task + "|---|---|---|---|---|"]
    for row in rows:
        curve = ", ".join(f"{v:,.1f}" for v in row["curve"][:-1])
        last = f"**{row['curve'][-1]:,.1f}**" if row["curve"] else ""
        final = ", ".join(f"`{name}` {_number(value)}" for name, value in row["final"].items())
        state = "" if row["complete"] else f" (unfinished, {row['frames']:,} frames)"
        first = f"| {row['task']} " if task else ""
        lines.append(
            f"{first}| {row['agent']} | {row['seed']} | {row['wall_seconds'] or 0:,.0f} s{state} | "
            f"{curve}{', ' if curve else ''}{last} | {final} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folders", type=Path, nargs="+", help="evaluation/run.py results folders")
    parser.add_argument("--task", action="store_true", help="a task column first")
    args = parser.parse_args(argv)
    for folder in args.folders:
        print(f"{folder}\n\n{markdown(cell_rows(folder), task=args.task)}\n")


if __name__ == "__main__":
    main()
