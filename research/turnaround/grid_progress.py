"""Markdown table of the cells of an evaluation/run.py results folder, finished or not (for long grids
such as research/turnaround/reproduce_fig2.sh, while they run or after an interruption).

    .venv/bin/python research/turnaround/grid_progress.py runs/fig2 [--json bench/results/fig2_progress.json]
    .venv/bin/python research/turnaround/grid_progress.py runs/fig2 --summary   # per preset, from summary.csv
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

from hyperstate.evaluation.cell import load_records, record_progress

COLUMNS = ("left_zone", "correct_direction", "stuck")


def rows(out: Path) -> list[dict]:
    table = []
    for record in load_records(out):
        cell = record_progress(record)
        table.append(
            {
                **{key: cell[key] for key in ("agent", "task", "seed", "complete", "frames")},
                "online_return": cell["curve"][-1] if cell["curve"] else None,
                "curve": [round(value, 1) for value in cell["curve"]],
                "wall_seconds": cell["wall_seconds"],
                **{key: cell["final"].get(key) for key in COLUMNS},
            }
        )
    return table


def markdown(table: list[dict]) -> str:
    lines = ["| agent | seed | frames | online return | left zone | correct direction | stuck | wall (s) |"]
    lines.append("|---|---|---|---|---|---|---|---|")
    for r in table:
        fmt = lambda v: "—" if v is None else f"{v:.2f}"  # noqa: E731
        status = "" if r["complete"] else " (running)"
        lines.append(
            f"| `{r['agent']}` | {r['seed']} | {r['frames'] / 1e6:.1f}M{status} | {fmt(r['online_return'])} | "
            f"{fmt(r['left_zone'])} | {fmt(r['correct_direction'])} | {fmt(r['stuck'])} | "
            f"{'—' if r['wall_seconds'] is None else round(r['wall_seconds'])} |"
        )
    return "\n".join(lines)


def summary_markdown(out: Path) -> str:
    """Per (agent, task) from OUT/summary.csv, with the mean wall time of its cells."""
    with (out / "summary.csv").open() as f:
        summary = list(csv.DictReader(f))
    walls: dict[tuple[str, str], list[float]] = {}
    for r in rows(out):
        if r["complete"] and r["wall_seconds"] is not None:
            walls.setdefault((r["agent"], r["task"]), []).append(r["wall_seconds"])

    def num(row: dict, key: str, spec: str = ".1f") -> str:
        return "—" if row.get(key) in (None, "") else format(float(row[key]), spec)

    lines = [
        "| agent | task | seeds | mean | IQM | 95 % CI | left zone | correct direction | stuck | coverage "
        "| probe KL after | wall per run (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in summary:
        wall = walls.get((row["agent"], row["task"]))
        lines.append(
            f"| `{row['agent']}` | {row['task']} | {row['seeds']} | {num(row, 'online_return_mean')} | "
            f"{num(row, 'online_return_iqm')} | [{num(row, 'ci95_low')}, {num(row, 'ci95_high')}] | "
            f"{num(row, 'left_zone', '.2f')} | {num(row, 'correct_direction', '.2f')} | {num(row, 'stuck', '.2f')} | "
            f"{num(row, 'final_coverage', '.3f')} | {num(row, 'probe_kl_after', '.4f')} | "
            f"{'—' if not wall else round(sum(wall) / len(wall))} |"
        )
    for task in dict.fromkeys(row["task"] for row in summary):
        row = next(r for r in summary if r["task"] == task)
        lines.append(
            f"\n{task}: task-aware reference {num(row, 'reference_return')}; Bayes-optimal bracket: "
            f"Bayes-adaptive reference (lower bound) {num(row, 'adaptive_reference_return')}, "
            f"optimistic estimate (upper) {num(row, 'bayes_estimate')}."
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--json", type=Path, default=None, help="also write the rows (with curves) here")
    parser.add_argument("--summary", action="store_true", help="one row per agent and task (needs summary.csv)")
    args = parser.parse_args()
    if args.summary:
        print(summary_markdown(args.out))
        return
    table = rows(args.out)
    print(markdown(table))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(table, indent=1))


if __name__ == "__main__":
    main()
