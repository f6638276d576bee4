"""Adds the certainty-equivalent deployment to finished task-aware cells of a grid, then re-reports.

Grids run before `final.certainty_equivalent` existed lack it; this deploys each finished reference
cell's saved agent (`agent.pt`) on the same held-out tasks and rewrites its record, `results.json`
and `summary.csv` (column `adaptive_reference_return`):

    python -m evaluation.reference OUT [--import MODULE ...]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from agents import Agent
from evaluation.cell import import_modules, load_records, write_json_atomic, write_results
from evaluation.deploy import certainty_equivalent_metrics, evaluation_tasks, reads_true_task
from evaluation.report import write_summary


def backfill(out: Path) -> list[str]:
    """Deploys every finished task-aware cell in `out` that lacks it; returns the cells it changed."""
    grid = json.loads((out / "grid.json").read_text()) if (out / "grid.json").exists() else {}
    changed = []
    for record_path in sorted((out / "cells").glob("*/record.json")):
        record = json.loads(record_path.read_text())
        final = record.get("final")
        agent_path = record_path.parent / "agent.pt"
        if not record.get("complete") or final is None or "certainty_equivalent" in final or not agent_path.exists():
            continue
        agent = Agent.load(agent_path)
        if not reads_true_task(agent):
            continue
        tasks = evaluation_tasks(record["task"], len(final["online_return_per_task"]))
        final["certainty_equivalent"] = certainty_equivalent_metrics(
            agent, record["task"], tasks, grid.get("episodes_per_task")
        )
        write_json_atomic(record_path, record)
        changed.append(record_path.parent.name)
    if changed:
        write_results(out)
        write_summary(out, load_records(out))
    return changed


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path, help="a grid's output directory (evaluation/run.py --out)")
    p.add_argument(
        "--import", dest="imports", nargs="+", default=[], metavar="MODULE", help="modules registering tasks"
    )
    args = p.parse_args(argv)
    if not (args.out / "cells").is_dir():
        p.error(f"{args.out} has no cells/ (not an evaluation/run.py output directory)")
    import_modules(args.imports)
    changed = backfill(args.out)
    print(f"{len(changed)} reference cells deployed Bayes-adaptively: {', '.join(changed) or '-'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
