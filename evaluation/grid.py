"""The results layout of a grid: every name and path under `--out`, in one place.

    OUT/grid.json                 the grid's arguments (what --resume must match)      driver
    OUT/commands.jsonl            every invocation on OUT: command, commit, processor,
                                  start, end and wall time                              driver
    OUT/results.json              one record per cell                                   driver
    OUT/summary.csv, OUT/figures/ the report                                            driver
    OUT/tb/<cell>/                tensorboard scalars                                   the cell
    OUT/cells/<cell>/             record.json, progress.json, checkpoint.pt,
                                  snapshots/agent_<frames>.pt, agent.pt,
                                  deployment.npz, coverage.npy, bonus_landscape.npz     the cell

A cell is `<agent>__<task>__s<seed>`. Cells write only their own folders; the driver (evaluation/run.py)
alone writes the grid-level files. A Ray cell works in the same layout under a folder of its own node and
keeps `cells/<cell>/` and `tb/<cell>/` in `--storage` under the same relative paths (evaluation/storage.py);
the driver writes what it returns into OUT.
"""

from __future__ import annotations

from pathlib import Path

SEPARATOR = "__"

GRID = "grid.json"
# One JSON line per invocation of the driver on OUT (a resumed grid has several): where its cells came from.
COMMANDS = "commands.jsonl"
RESULTS = "results.json"
SUMMARY = "summary.csv"
FIGURES = "figures"
TENSORBOARD = "tb"
CELLS = "cells"
RECORD = "record.json"
AGENT = "agent.pt"
DEPLOYMENT = "deployment.npz"
COVERAGE = "coverage.npy"
PROGRESS = "progress.json"
# The training-log values averaged into the next curve point, one JSON line per iteration since the last point.
POINT_LOG = "point_log.jsonl"
SNAPSHOTS = "snapshots"


def cell_id(agent: str, task: str, seed: int) -> str:
    return f"{agent}{SEPARATOR}{task}{SEPARATOR}s{seed}"


def record_cell_id(record: dict) -> str:
    """The cell id of a `results.json` record."""
    return cell_id(record["agent"], record["task"], record["seed"])


def parse_cell_id(cell: str) -> tuple[str, str, int]:
    """(agent, task, seed) of a cell id; ValueError if it is not one."""
    parts = cell.split(SEPARATOR)
    if len(parts) != 3 or not parts[2].startswith("s") or not parts[2][1:].isdigit():
        raise ValueError(f"{cell!r} is not a cell id (<agent>{SEPARATOR}<task>{SEPARATOR}s<seed>)")
    return parts[0], parts[1], int(parts[2][1:])


def cell_dir(out: Path, cell: str) -> Path:
    return Path(out) / CELLS / cell


def cell_ids(out: Path) -> list[str]:
    """The cells that have a folder under `out`, sorted."""
    cells = Path(out) / CELLS
    return sorted(p.name for p in cells.iterdir() if p.is_dir()) if cells.is_dir() else []


def snapshot_path(out: Path, cell: str, frames: int) -> Path:
    return cell_dir(out, cell) / SNAPSHOTS / f"agent_{frames:09d}.pt"


def snapshots(out: Path, cell: str) -> list[tuple[int, Path]]:
    """(frames, path) of the agent kept at each evaluation point, in order."""
    return snapshots_in(cell_dir(out, cell))


def snapshots_in(directory: Path) -> list[tuple[int, Path]]:
    """`snapshots` of a cell folder given by its path (wherever it lies)."""
    paths = sorted((Path(directory) / SNAPSHOTS).glob("agent_*.pt"))
    return [(int(path.stem.split("_")[1]), path) for path in paths]
