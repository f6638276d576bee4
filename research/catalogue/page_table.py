"""A task's results-page table from its committed grid: per agent, the online return of each seed, the
mean, the seeds that solve the task and the means of the named final-deployment metrics.

    .venv/bin/python research/catalogue/page_table.py docs/results/point_treasure_sparse \
        goal_reached last_episode_at_goal

A page holds the table between `<!-- task-table: GRID METRIC ... [--decimals=N] [--share] -->` and
`<!-- /task-table -->`, blank lines around it; tests/test_docs.py checks that it is what this prints.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hyperstate.evaluation.cross_task import task_table


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("grid", type=Path, help="one task's grid (a folder with cells/)")
    parser.add_argument("metrics", nargs="*", help="final-deployment metrics to give the seeds' mean of")
    parser.add_argument("--decimals", type=int, default=1, help="decimals of the online returns")
    parser.add_argument("--share", action="store_true", help="the solved seeds' share and its Wilson 95 %% interval")
    args = parser.parse_args(argv)
    say = lambda m: print(m, file=sys.stderr)  # noqa: E731
    sys.stdout.write(task_table(args.grid, args.metrics, args.decimals, share=args.share, say=say))
    return 0


if __name__ == "__main__":
    sys.exit(main())
