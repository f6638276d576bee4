"""A task's results-page table from its committed grid: per agent, the online return of each seed, the
mean, the seeds that solve the task and the means of the named final-deployment metrics.

    .venv/bin/python research/catalogue/page_table.py docs/results/point_treasure_sparse \
        goal_reached last_episode_at_goal

A page holds the table between `<!-- task-table: GRID METRIC ... [--decimals=N] [--share] -->` and
`<!-- /task-table -->`, blank lines around it; tests/test_docs.py checks that it is what this prints.
After a merge, `--update PAGE...` rewrites every such table of the pages from their markers:

    .venv/bin/python research/catalogue/page_table.py --update docs/results/point_treasure_sparse.md
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from hyperstate.evaluation.cross_task import task_table

MARKED = re.compile(r"(<!-- task-table: (?P<args>[^>]*?) -->\n\n)(?P<table>.*?)(\n<!-- /task-table -->)", re.S)


def update(page: Path, root: Path, say) -> int:
    """Rewrites the page's marked tables from their grids (paths relative to `root`); the number changed."""
    changed = 0

    def table(match: re.Match) -> str:
        nonlocal changed
        args = parser().parse_args(match.group("args").split())
        new = task_table(root / args.grid, args.metrics, args.decimals, share=args.share, say=say)
        changed += new != match.group("table")
        return match.group(1) + new + match.group(4)

    text = page.read_text()
    new_text = MARKED.sub(table, text)
    if new_text != text:
        page.write_text(new_text)
    return changed


def parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("grid", type=Path, nargs="?", help="one task's grid (a folder with cells/)")
    parser.add_argument("metrics", nargs="*", help="final-deployment metrics to give the seeds' mean of")
    parser.add_argument("--decimals", type=int, default=1, help="decimals of the online returns")
    parser.add_argument("--share", action="store_true", help="the solved seeds' share and its Wilson 95 %% interval")
    parser.add_argument("--update", type=Path, nargs="+", metavar="PAGE", help="rewrite these pages' marked tables")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    say = lambda m: print(m, file=sys.stderr)  # noqa: E731
    if args.update:
        for page in args.update:
            print(f"{page}: {update(page, Path.cwd(), say)} table(s) changed")
        return 0
    if args.grid is None:
        parser().error("name a grid, or --update PAGE...")
    sys.stdout.write(task_table(args.grid, args.metrics, args.decimals, share=args.share, say=say))
    return 0


if __name__ == "__main__":
    sys.exit(main())
