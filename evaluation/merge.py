"""Gather the finished cells of several grids into one grid, and report it as evaluation/run.py does.

    python evaluation/merge.py --into docs/results/fig2_grid runs/fig2_part1 runs/fig2_part2 [...]

A grid too long for one machine or one session runs in parts — several `evaluation/run.py --out` folders,
each with some agents or seeds — and is merged here, as often as parts finish: cells already in `--into`
stay, new finished cells are added, and the report (results.json, summary.csv, figures/) is rewritten from
all of them. `--into` keeps only what the report needs and what is small enough to commit: each cell's
record.json, deployment.npz and coverage.npy (`--with-agent` adds the final agent.pt); no checkpoints,
snapshots or tensorboard logs.

A merged grid is one experiment, so the parts must agree: every cell has the same training budget, evaluation
points and held-out tasks, and all seeds of one agent were trained with one configuration. A part that breaks
this is refused with the differences named, and nothing is written. Unfinished cells are listed and left
out. `OUT/sources.json` says where each cell came from: the part's folder, its grid arguments, the
git commit of the code that trained it and the part's command lines (its `commands.jsonl`). A part that is
itself a merged grid (a committed results folder) passes on its own sources.json entries, with `via`
naming it. `--agents` takes only some agents' cells, e.g.
to pool the seeds of two agents from two committed grids:

    python evaluation/merge.py --into docs/results/seeds docs/results/grid runs/more --agents hyperx oracle_rh
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from hyperstate.agents.config import RUNTIME_FIELDS, AgentConfig, agent_settings, from_dict
from hyperstate.evaluation import cli, grid, provenance
from hyperstate.evaluation.cell import load_records, write_results
from hyperstate.evaluation.report import text_table, write_figures, write_summary
from hyperstate.files import write_json_atomic

SOURCES = "sources.json"
# What a merged cell keeps: the record and what the report draws from; agent.pt only with --with-agent.
CELL_FILES = (grid.RECORD, grid.DEPLOYMENT, grid.COVERAGE)


class MergeError(Exception):
    """Parts that do not make one grid: reported in one message, nothing written."""


def _flatten(config: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in config.items():
        if isinstance(value, dict):
            out.update(_flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def comparable(config: dict) -> dict:
    """A record's agent config as this code reads it (fields added since it ran at the values that reproduce
    the code it ran), without the runtime fields, which results do not depend on."""
    try:
        return agent_settings(from_dict(AgentConfig, config))
    except (ValueError, TypeError, KeyError):  # an agent of your own: its config as recorded
        return {k: v for k, v in config.items() if k not in RUNTIME_FIELDS}


def config_differences(a: dict, b: dict) -> list[str]:
    """The dotted fields in which two agents' settings differ, as 'field: a != b'."""
    fa, fb = _flatten(comparable(a)), _flatten(comparable(b))
    return [f"{k}: {fa.get(k)!r} != {fb.get(k)!r}" for k in sorted(set(fa) | set(fb)) if fa.get(k) != fb.get(k)]


def _describe_cell(record: dict, source: Path) -> dict:
    """What a merged cell must share with the rest of its grid, and where it came from (a merged part's own
    entry for the cell, with `via` naming the part)."""
    merged_sources = source / SOURCES
    if merged_sources.exists():
        entry = json.loads(merged_sources.read_text()).get(grid.record_cell_id(record))
        if entry is not None:
            return {**entry, "via": str(source)}
    grid_file = source / grid.GRID
    arguments = json.loads(grid_file.read_text()) if grid_file.exists() else {}
    return {
        "source": str(source),
        "budget": arguments.get("frames", record["frames"]),  # as asked; record["frames"] rounds to iterations
        "eval_tasks": len(record["final"]["online_return_per_task"]),
        # The learning curves of one figure are averaged point by point.
        "eval_every": arguments.get("eval_every", record["curve"][0]["frames"] if record["curve"] else None),
        "overrides": arguments.get("overrides", {}).get(record["agent"]),
        "git_commit": record.get("versions", {}).get("git_commit"),
        # The part's invocations (evaluation/run.py writes them; a part written before it did has none).
        "commands": provenance.read_commands(source / grid.COMMANDS),
    }


def plan(
    into: Path, parts: list[Path], replace: bool = False, agents: tuple[str, ...] | None = None
) -> tuple[dict[str, Path], dict[str, dict], list[str]]:
    """The cells to copy ({cell: part folder}; only `agents`' where given), `into`'s sources.json as it will
    be after the copy, and the notes to print (cells left out); MergeError if the parts and the cells
    already in `into` do not make one grid."""
    sources_path = into / SOURCES
    known: dict[str, dict] = json.loads(sources_path.read_text()) if sources_path.exists() else {}
    records = {grid.record_cell_id(r): r for r in load_records(into)}
    copies: dict[str, Path] = {}
    notes: list[str] = []
    found = set()
    for part in parts:
        if not (part / grid.CELLS).is_dir():
            raise MergeError(f"{part} holds no grid (no {grid.CELLS}/ folder)")
        for record in load_records(part):
            if agents is not None and record["agent"] not in agents:
                continue
            found.add(record["agent"])
            cell = grid.record_cell_id(record)
            if not record.get("complete") or record.get("final") is None:
                last = record["curve"][-1]["frames"] if record.get("curve") else 0
                notes.append(f"{cell} in {part}: not finished ({last:,} of {record['frames']:,} frames), left out")
                continue
            if cell in copies:
                raise MergeError(f"{cell} is in two parts: {copies[cell]} and {part}")
            if cell in records and not replace:
                if records[cell].get("curve") == record.get("curve") and records[cell]["final"] == record["final"]:
                    continue  # merged before
                raise MergeError(f"{cell} is already in {into} with other results (--replace to take {part}'s)")
            copies[cell] = part
            records[cell] = record
            known[cell] = _describe_cell(record, part)
    missing = sorted(set(agents or ()) - found)
    if missing:
        raise MergeError(f"no cell of {', '.join(missing)} in {', '.join(map(str, parts))}")
    problems = grid_problems(known, records)
    if problems:
        raise MergeError("the parts do not make one grid:\n  " + "\n  ".join(problems))
    return copies, known, notes


def grid_problems(known: dict[str, dict], records: dict[str, dict]) -> list[str]:
    """Why `records` (with their sources `known`) are not one grid: budgets, evaluation points or held-out
    tasks that differ between cells, seeds of one agent trained with different configs. Empty if they are."""
    problems = []
    shared = (("budget", "training budgets"), ("eval_every", "evaluation points"), ("eval_tasks", "held-out tasks"))
    for key, what in shared:
        values = {c: d[key] for c, d in known.items() if c in records}
        if len(set(values.values())) > 1:
            problems.append(f"{what} differ: " + ", ".join(f"{c} {v}" for c, v in sorted(values.items())))
    by_agent: dict[tuple[str, str], list[dict]] = {}
    for record in records.values():
        by_agent.setdefault((record["agent"], record["task"]), []).append(record)
    for (agent, task), cells in sorted(by_agent.items()):
        first = min(cells, key=lambda r: r["seed"])
        for other in cells:
            differences = config_differences(first["config"], other["config"])
            if differences:
                problems.append(
                    f"{agent} on {task}: seed {other['seed']} was trained with another config than seed "
                    f"{first['seed']} ({'; '.join(differences[:5])}{' ...' if len(differences) > 5 else ''})"
                )
    return problems


def merge(
    into: Path,
    parts: list[Path],
    with_agent: bool = False,
    replace: bool = False,
    agents: tuple[str, ...] | None = None,
) -> tuple[list[str], list[dict]]:
    """Copies the finished cells of `parts` (only `agents`' where given) into `into` and rewrites its report;
    returns the notes and the summary rows."""
    copies, sources, notes = plan(into, parts, replace, agents)
    files = CELL_FILES + ((grid.AGENT,) if with_agent else ())
    for cell, part in sorted(copies.items()):
        target = grid.cell_dir(into, cell)
        if target.exists():
            shutil.rmtree(target)
        target.mkdir(parents=True)
        for name in files:
            path = grid.cell_dir(part, cell) / name
            if path.exists():
                shutil.copy2(path, target / name)
        notes.append(f"{cell}: from {part}")
    into.mkdir(parents=True, exist_ok=True)
    write_json_atomic(into / SOURCES, dict(sorted(sources.items())))
    write_results(into)
    records = load_records(into)
    rows = write_summary(into, records)
    write_figures(into, records)
    return notes, rows


def main(argv: list[str] | None = None) -> int:
    p = cli.OneLineParser(
        prog=cli.program_name("evaluation/merge.py"),
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("parts", nargs="+", type=Path, metavar="PART", help="evaluation/run.py --out folders")
    p.add_argument("--into", type=Path, required=True, help="the merged grid (created, or added to)")
    p.add_argument("--with-agent", action="store_true", help="also keep each cell's final agent.pt")
    p.add_argument("--replace", action="store_true", help="a part's cell replaces the same cell already merged")
    p.add_argument("--agents", nargs="+", metavar="AGENT", help="take only these agents' cells from the parts")
    args = p.parse_args(argv)
    agents = tuple(args.agents) if args.agents else None
    swallowed = [a for a in agents or () if (Path(a) / "results.json").exists()]
    if swallowed:  # `--agents a b PART`: argparse hands the part folders to --agents
        p.error(f"--agents took the part folder {swallowed[0]} for an agent name: put --agents after the parts")
    try:
        notes, rows = merge(args.into, args.parts, args.with_agent, args.replace, agents)
    except MergeError as e:
        print(f"{cli.program_name('evaluation/merge.py')}: error: {e}", file=sys.stderr)
        return 2
    print(*notes, sep="\n")
    print()
    print(text_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
