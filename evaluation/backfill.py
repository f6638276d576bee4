"""Brings a finished grid up to the current metrics, without retraining, then re-reports.

Grids run by older code lack some of what `evaluation/run.py` records now. This fills in, per finished
cell, what can be derived from what the cell saved:
- `final.certainty_equivalent` of task-aware reference cells: the saved agent (`agent.pt`) deployed
  Bayes-adaptively on the same held-out tasks (`summary.csv` column `adaptive_reference_return`);
- the belief probe per BAMDP step (`final.probe_kl_per_step`, `probe_accuracy_per_step`), refit from
  the final deployment's features and exact beliefs (`deployment.npz`); the probe is seeded, so the
  aggregate scores it recomputes equal the recorded ones;
then rewrites `results.json`, `summary.csv` and the figures.

    python -m hyperstate.evaluation.backfill OUT [--import MODULE ...]
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

# Nothing here renders: name no OpenGL backend and dm_control would try GLFW and warn about DISPLAY.
os.environ.setdefault("MUJOCO_GL", "disable")

from hyperstate import suite
from hyperstate.evaluation import grid, protocol
from hyperstate.evaluation.cell import import_modules, load_records, write_json_atomic, write_results
from hyperstate.evaluation.deploy import certainty_equivalent_metrics, evaluation_tasks, reads_true_task
from hyperstate.evaluation.probe import belief_quality
from hyperstate.evaluation.report import write_figures, write_summary


def _certainty_equivalent(record: dict, directory: Path, arguments: dict) -> bool:
    final = record["final"]
    agent_path = directory / grid.AGENT
    if "certainty_equivalent" in final or not agent_path.exists():
        return False
    agent = protocol.load_agent(record["agent"], agent_path)
    if not reads_true_task(agent):
        return False
    tasks = evaluation_tasks(record["task"], len(final["online_return_per_task"]))
    final["certainty_equivalent"] = certainty_equivalent_metrics(
        agent, record["task"], tasks, arguments.get("episodes_per_task")
    )
    return True


def _probe_per_step(record: dict, directory: Path) -> bool:
    final = record["final"]
    npz = directory / grid.DEPLOYMENT
    if "probe_kl_per_step" in final or "probe_kl" not in final or not npz.exists():
        return False
    data = np.load(npz)
    if "obs_belief" not in data:
        return False
    # The exact belief when each action was chosen: the prior, then the belief each step ended in.
    after = data["obs_belief"]
    prior = np.broadcast_to(suite.load(record["task"], seed=0).task.prior_belief(), after.shape[1:])
    exact = np.concatenate([prior[None], after[:-1]])
    final.update(belief_quality(data["features"], exact))
    return True


def backfill(out: Path) -> list[str]:
    """Fills in the finished cells of `out`; returns '<cell>: <what>' for everything it added."""
    arguments = json.loads((out / grid.GRID).read_text()) if (out / grid.GRID).exists() else {}
    added = []
    for record_path in sorted((out / grid.CELLS).glob(f"*/{grid.RECORD}")):
        record = json.loads(record_path.read_text())
        if not record.get("complete") or record.get("final") is None:
            continue
        directory = record_path.parent
        what = []
        if _certainty_equivalent(record, directory, arguments):
            what.append("certainty_equivalent")
        if _probe_per_step(record, directory):
            what.append("probe per step")
        if what:
            write_json_atomic(record_path, record)
            added.append(f"{directory.name}: {', '.join(what)}")
    if added:
        write_results(out)
    records = load_records(out)
    write_summary(out, records)
    write_figures(out, records)
    return added


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path, help="a grid's output directory (evaluation/run.py --out)")
    p.add_argument(
        "--import", dest="imports", nargs="+", default=[], metavar="MODULE", help="modules registering tasks"
    )
    args = p.parse_args(argv)
    if not (args.out / grid.CELLS).is_dir():
        p.error(f"{args.out} has no cells/ (not an evaluation/run.py output directory)")
    import_modules(args.imports)
    added = backfill(args.out)
    print("\n".join(added) if added else "nothing to add")
    print(f"{len(added)} cells updated; summary.csv and figures rewritten in {args.out}/")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
