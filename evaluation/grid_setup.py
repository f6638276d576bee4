"""Setting a grid up from the command line: names, settings and budgets checked, the output folder
prepared (a new grid, a resumed one, an extended one, or a refusal to mix grids)."""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path
from typing import Any

from hyperstate import agents, suite
from hyperstate.evaluation import grid as grid_layout
from hyperstate.evaluation import protocol
from hyperstate.evaluation.cli import UsageError
from hyperstate.evaluation.imports import import_modules
from hyperstate.evaluation.report import REFERENCE_AGENT
from hyperstate.files import write_json_atomic
from hyperstate.registry import unknown_name


def load_config_file(path: Path | None) -> dict:
    if path is None:
        return {}
    if not path.exists():
        raise UsageError(f"--config {path}: no such file")
    text = path.read_text()
    if path.suffix == ".toml":
        import tomllib

        data = tomllib.loads(text)
    elif path.suffix in (".yaml", ".yml"):
        import yaml

        data = yaml.safe_load(text) or {}
    else:
        raise UsageError(f"--config {path}: use a .toml, .yaml or .yml file")
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise UsageError(f"--config {path}: expected tables of overrides per preset name (or 'all')")
    return data


def check_tasks(names: list[str]) -> None:
    """UsageError, with did-you-mean, for a task nobody registered."""
    for name in names:
        if name not in suite.TASKS:
            raise UsageError(str(unknown_name("task", name, suite.TASKS, "tasks")))


def build_grid(args: argparse.Namespace) -> tuple[list[str], dict[str, dict]]:
    """Validates names and overrides; returns the agent list and each agent's overrides."""
    try:
        import_modules(args.imports)
    except Exception as e:  # noqa: BLE001  (any failure of user code is reported as a usage error)
        raise UsageError(f"--import: {type(e).__name__}: {e}") from None
    check_numbers(args)
    check_tasks(args.tasks)
    for name in args.agents:
        try:
            protocol.check_name(name)
        except ValueError as e:
            raise UsageError(str(e)) from None
    config = read_config_files(args.config)
    names = list(dict.fromkeys(args.agents + ([] if args.no_reference else [REFERENCE_AGENT])))
    return names, {name: agent_overrides(name, config, args.frames) for name in names}


def check_numbers(args: argparse.Namespace) -> None:
    """The numeric options are in range; UsageError naming the first that is not."""
    if args.frames <= 0:
        raise UsageError(f"--frames must be positive, got {args.frames}")
    if args.physics_threads is not None and args.physics_threads < 1:
        raise UsageError(f"--physics-threads must be positive, got {args.physics_threads}")
    if args.eval_tasks < 1 or (args.eval_every is not None and args.eval_every < 1):
        raise UsageError("--eval-tasks and --eval-every must be positive")
    if args.video_tasks < 1:
        raise UsageError(f"--video-tasks must be positive, got {args.video_tasks}")
    if args.episodes_per_task is not None and args.episodes_per_task < 1:
        raise UsageError(f"--episodes-per-task must be positive, got {args.episodes_per_task}")


def read_config_files(paths: list[Path]) -> dict[str, dict]:
    """The `--config` files' tables merged in order ({agent or "all": {setting: value}}); tables for
    presets outside this grid are fine (one file can serve several grids), other names are typos."""
    config: dict[str, dict] = {}
    for path in paths:
        for table, values in load_config_file(path).items():
            config[table] = {**config.get(table, {}), **values}
    unknown = set(config) - set(protocol.agent_names()) - {"all"}
    if unknown:
        raise UsageError(f"--config has tables for unknown agents: {', '.join(sorted(unknown))}")
    return config


def agent_overrides(name: str, config: dict[str, dict], frames: int) -> dict:
    """Agent `name`'s overrides from the config tables, checked by building it (and its budget)."""
    merged = {**config.get("all", {}), **config.get(name, {})}
    try:
        agent = protocol.make_agent(name, **merged)
    except (ValueError, TypeError) as e:
        raise UsageError(f"--config for {name}: {e}") from None
    if isinstance(getattr(agent, "config", None), agents.AgentConfig):
        try:
            agents.check_budget(agent.config, frames)
        except ValueError as e:
            raise UsageError(f"{name}: {e}") from None
    return merged


def incompatible_cells(args: argparse.Namespace, names: list[str], overrides: dict[str, dict]) -> dict:
    """{(agent, task): reason} for the pairs that cannot run, e.g. `oracle` on a task without an exact belief."""
    task_kwargs = {} if args.episodes_per_task is None else {"episodes_per_task": args.episodes_per_task}
    skipped = {}
    for task in args.tasks:
        for name in names:
            try:
                protocol.check_task(protocol.make_agent(name, **overrides[name]), task, task_kwargs)
            except ValueError as e:
                skipped[(name, task)] = str(e)
    return skipped


def prepare_out(args: argparse.Namespace, grid: dict) -> None:
    """Refuses to mix grids or overwrite results unless asked (--resume / --force)."""
    out: Path = args.out
    grid_file = out / grid_layout.GRID
    if args.force and out.exists():
        shutil.rmtree(out)
    has_results = grid_file.exists() or (out / grid_layout.RESULTS).exists() or (out / grid_layout.CELLS).exists()
    if has_results:
        previous = read_json_file(grid_file) if grid_file.exists() else None
        if not args.resume:
            what = "this grid" if previous == grid else "a different grid"
            raise UsageError(
                f"--out {out} holds results of {what}; pass --resume to continue it or --force to overwrite"
            )
        if previous is not None and _extends(previous, grid, args):
            grid["eval_every"] = previous["eval_every"]
            _check_extension(grid)
        elif previous != grid:
            raise UsageError(
                f"--out {out} holds results of a different grid; --resume needs the same arguments, or a larger "
                "--frames to extend it (or use --force or another --out)"
            )
        for record in sorted((out / grid_layout.CELLS).glob(f"*/{grid_layout.RECORD}")):
            read_json_file(record)
    if args.storage is not None:
        _prepare_storage(args)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(grid_file, grid)


def read_json_file(path: Path) -> Any:
    """The JSON in `path`; UsageError naming the file if it is not whole (a partial copy, say)."""
    try:
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise UsageError(
            f"{path} is unreadable ({type(e).__name__}: {e}); this program writes it whole, so it is damaged or "
            f"a partial copy: restore it, or delete {path.parent} to run that part again"
        ) from None


def _extends(previous: dict, grid: dict, args: argparse.Namespace) -> bool:
    """Whether `grid` is `previous` with a larger budget (and the same evaluation points)."""
    if grid["frames"] <= previous.get("frames", 0):
        return False
    if args.eval_every is not None and args.eval_every != previous.get("eval_every"):
        return False
    same = {k: v for k, v in grid.items() if k not in ("frames", "eval_every")}
    return same == {k: v for k, v in previous.items() if k not in ("frames", "eval_every")}


def _check_extension(grid: dict) -> None:
    """Refuses to extend a grid whose agents' training would differ from a run started with the new budget."""
    for name in grid["agents"]:
        config = getattr(protocol.make_agent(name, **grid["overrides"][name]), "config", None)
        reason = (
            agents.budget_dependence(config)
            if isinstance(config, agents.AgentConfig)
            else ("its schedules cannot be checked (not an agents.AgentConfig)")
        )
        if reason is not None:
            raise UsageError(f"cannot extend {name} to {grid['frames']:,} frames: {reason}")


def _prepare_storage(args: argparse.Namespace) -> None:
    """A Ray grid's cells resume from whatever their storage holds: start only on an empty one unless
    --resume (--force empties it)."""
    from hyperstate.evaluation import storage

    if args.executor != "ray":
        raise UsageError("--storage is where Ray cells keep their files; the local executor works in --out")
    try:
        if args.force:
            storage.clear(args.storage)
        elif not args.resume and storage.holds_cells(args.storage):
            raise UsageError(
                f"--storage {args.storage} holds cells of an earlier run; pass --resume to continue them "
                "or --force to delete them"
            )
    except (ImportError, OSError, ValueError) as e:
        raise UsageError(f"--storage {args.storage}: {type(e).__name__}: {e}") from None
