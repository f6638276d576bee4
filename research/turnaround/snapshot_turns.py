"""When does a run learn the turn-around? Deploy a cell's kept snapshots again and measure each.

    .venv/bin/python research/turnaround/snapshot_turns.py runs/fig2_20m/cells/hyperx__cheetah_dir_sparse__s1 \
        [--every 4] [--import research/turnaround/fig2_presets.py]

Every `--every`-th agent in the cell's `snapshots/` (the harness keeps one per evaluation point) is
loaded and deployed on the 20 held-out tasks with deterministic actions, as at the evaluation points;
prints the online return and the task's turn-around metrics (`turned_around`, the mean return of the
deployments whose first exit was wrong, `correct_direction`). Task: `cheetah_dir_sparse`.
`--json OUT.json` also writes, per snapshot, its frames, online return and every metric the task declares
(`suite.exploration_metrics`: `return_forward`, `return_backward`, `stuck`, ...), for docs/results/.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import torch  # noqa: E402

from hyperstate import agents  # noqa: E402
from hyperstate.evaluation import grid  # noqa: E402
from hyperstate.evaluation.deploy import deploy, evaluation_tasks, exploration_metric_means  # noqa: E402
from hyperstate.evaluation.imports import import_modules  # noqa: E402

TASK = "cheetah_dir_sparse"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("cell", type=Path)
    parser.add_argument("--every", type=int, default=4)
    parser.add_argument("--import", dest="imports", nargs="*", default=[], help="preset files the cell used")
    parser.add_argument("--json", type=Path, help="also write every snapshot's metrics to this file")
    args = parser.parse_args()
    import_modules(args.imports)
    torch.set_num_threads(1)
    tasks = evaluation_tasks(TASK, 20)
    snapshots = grid.snapshots_in(args.cell)

    def f(value: float | None, spec: str) -> str:  # None: the metric applies to no deployment
        return "—" if value is None else format(value, spec)

    records = []
    for frames, path in snapshots[args.every - 1 :: args.every]:
        deployment = deploy(agents.Agent.load(path), TASK, tasks)
        means = exploration_metric_means(TASK, deployment.observations, deployment.rewards, deployment.tasks)
        online_return = float(deployment.rewards.sum(0).mean())
        records.append({"frames": frames, "online_return": online_return, **means})
        print(
            f"{frames / 1e6:5.1f}M  online return {online_return:6.0f}  "
            f"turned {f(means['turned_around'], '.2f')}  R wrong-first {f(means['return_wrong_first'], '6.0f')}  "
            f"correct direction {f(means['correct_direction'], '.2f')}"
        )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"cell": str(args.cell), "task": TASK, "snapshots": records}, indent=1))


if __name__ == "__main__":
    main()
