"""Markdown table of the cells of an evaluation/run.py results folder, finished or not (for long grids
such as bench/reproduce_fig2.sh, while they run or after an interruption).

    .venv/bin/python bench/grid_progress.py runs/fig2 [--json bench/results/fig2_progress.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

COLUMNS = ("left_zone", "correct_direction", "stuck")


def rows(out: Path) -> list[dict]:
    table = []
    for record_file in sorted(out.glob("cells/*/record.json")):
        r = json.loads(record_file.read_text())
        curve = r.get("curve") or []
        final = r.get("final") or {}
        table.append(
            {
                "agent": r["agent"],
                "task": r["task"],
                "seed": r["seed"],
                "complete": bool(r.get("complete")),
                "frames": curve[-1]["frames"] if curve else 0,
                "online_return": curve[-1]["online_return"] if curve else None,
                "curve": [round(p["online_return"], 1) for p in curve],
                "wall_seconds": curve[-1].get("wall_seconds") if curve else None,
                **{k: final.get(k) for k in COLUMNS},
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--json", type=Path, default=None, help="also write the rows (with curves) here")
    args = parser.parse_args()
    table = rows(args.out)
    print(markdown(table))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(table, indent=1))


if __name__ == "__main__":
    main()
