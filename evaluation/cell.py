"""One cell of the grid: train one agent on one task with one seed, evaluating as it goes.

Everything a cell writes lives in `OUT/cells/<agent>__<task>__s<seed>/` (and its tensorboard scalars in
`OUT/tb/<cell>/`): `record.json` (rewritten atomically after every evaluation point), the agent's
training checkpoint, the agent at every evaluation point (`snapshots/`), the final agent, and the final
deployment's trajectories (`deployment.npz`); while it trains, also `point_log.jsonl` (the logged values
the next curve point averages, so that a resumed cell averages them as an uninterrupted one does). A cell
never writes the grid-level files: the driver (evaluation/run.py) alone writes `results.json`,
`summary.csv` and the figures, so parallel cells never touch a shared file. A cell whose record says
`complete` is never re-run (on --resume it is only brought up to the current metrics,
evaluation/upgrade.py); an incomplete one resumes from its checkpoint.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from hyperstate import suite
from hyperstate.evaluation import cli, grid, protocol
from hyperstate.evaluation.coverage import HyperStateCoverage
from hyperstate.evaluation.deploy import (
    certainty_equivalent_metrics,
    deploy,
    deployment_metrics,
    evaluation_tasks,
    reads_true_task,
)
from hyperstate.evaluation.upgrade import upgrade_record
from hyperstate.files import write_bytes_atomic


@dataclasses.dataclass(frozen=True)
class CellSpec:
    """What one cell runs."""

    agent: str
    task: str
    seed: int
    frames: int
    eval_every: int
    eval_tasks: int
    episodes_per_task: int | None
    overrides: dict
    out: str
    resume: bool
    progress: bool = False  # the agent's own progress bar (evaluation/run.py draws one view of all cells instead)
    position: int = 0
    imports: tuple[str, ...] = ()  # user modules that register tasks and agents, imported in the worker first
    # (.py path as given, its source) for each .py import, read by the driver: a Ray cell imports these, so a
    # node needs no copy of the user's files (evaluation/remote.py).
    import_sources: tuple[tuple[str, str], ...] = ()
    physics_threads: int = 0  # the cores this cell may use for physics (0: all); parallel cells share them
    storage: str | None = None  # where a Ray cell keeps its files between attempts (evaluation/storage.py)

    @property
    def cell_id(self) -> str:
        return grid.cell_id(self.agent, self.task, self.seed)

    @property
    def directory(self) -> Path:
        return grid.cell_dir(Path(self.out), self.cell_id)


def save_array_atomic(path: Path, array: np.ndarray) -> None:
    """`array` as a .npy file, written atomically (`write_bytes_atomic`)."""
    buffer = io.BytesIO()
    np.save(buffer, array)
    write_bytes_atomic(path, buffer.getvalue())


def write_json_atomic(path: Path, data: Any) -> None:
    """`data` as JSON, written atomically (`write_bytes_atomic`)."""
    write_bytes_atomic(path, json.dumps(data, indent=1, default=_json_default).encode())


def report_failure(spec: CellSpec, error: BaseException) -> str:
    """Prints one line about a failed cell to stderr and returns it."""
    line = f"{spec.cell_id}: {type(error).__name__}: {error}".splitlines()[0]
    command = cli.program_name("evaluation/run.py")
    print(f"{command}: cell failed (the others go on; --resume retries it): {line}", file=sys.stderr)
    return line


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def versions() -> dict:
    """Package versions, the git commit of the code and the processor that produced a result."""
    out = {"python": platform.python_version()}
    for package in ("hyperstate", "torch", "mujoco", "dm-control", "numpy"):
        try:
            out[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            out[package] = None
    try:
        root = Path(__file__).resolve().parents[1]
        out["git_commit"] = (
            subprocess.run(
                ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10
            ).stdout.strip()
            or None
        )
    except (OSError, subprocess.SubprocessError):
        out["git_commit"] = None
    out["cpu"] = cpu_description()
    return out


def cpu_description() -> str:
    """The processor and its widest vector unit: a run's floats, and so its learning curve, depend on them."""
    model, flags = platform.processor() or platform.machine(), set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and value.strip():
                model = value.strip()
            elif key.strip() == "flags":
                flags = set(value.split())
            if flags and model:
                break
    except OSError:
        pass
    vector = next((f for f in ("avx512f", "avx2", "avx", "neon", "asimd") if f in flags), None)
    return f"{model} ({vector})" if vector else model


def read_import_sources(names: tuple[str, ...] | list[str]) -> tuple[tuple[str, str], ...]:
    """(path, source) of every .py file among `--import` names, for cells on other machines."""
    return tuple((name, Path(name).read_text()) for name in names if name.endswith(".py"))


def materialize_imports(imports: tuple[str, ...], sources: tuple[tuple[str, str], ...]) -> tuple[str, ...]:
    """`imports` with each shipped .py file replaced by a copy of its source on this machine.

    The copy keeps the file's name (its module name: what registers the user's tasks and agents) in a
    folder named by the source's hash, so a worker that runs several cells imports the same file again
    (a no-op) and a changed source is never taken for the old one.
    """
    import hashlib
    import tempfile

    shipped = dict(sources)
    local = []
    for name in imports:
        if name not in shipped:
            local.append(name)
            continue
        source = shipped[name]
        digest = hashlib.sha256(source.encode()).hexdigest()[:16]
        path = Path(tempfile.gettempdir()) / "hyperstate-imports" / digest / Path(name).name
        if not path.exists():  # the folder is named by the source's hash: an existing copy is this source
            path.parent.mkdir(parents=True, exist_ok=True)
            write_bytes_atomic(path, source.encode())
        local.append(str(path))
    return tuple(local)


def import_modules(names: tuple[str, ...] | list[str]) -> None:
    """Imports modules by name or .py path (user tasks register themselves with suite on import)."""
    import importlib
    import importlib.util
    import sys

    for name in names:
        if name.endswith(".py"):
            module_name = Path(name).stem
            if module_name in sys.modules:
                # The same file again is a no-op; another module of that name (a file with the same stem, or
                # a library such as `json`) would otherwise be taken silently for this file.
                loaded = getattr(sys.modules[module_name], "__file__", None)
                if loaded is not None and Path(loaded).resolve() == Path(name).resolve():
                    continue
                raise ImportError(
                    f"{name}: a module named {module_name!r} is already imported (from {loaded or 'a built-in'}); "
                    "rename the file"
                )
            spec = importlib.util.spec_from_file_location(module_name, name)
            if spec is None or spec.loader is None:
                raise ImportError(f"cannot import {name}")
            module = importlib.util.module_from_spec(spec)
            sys.modules[module_name] = module
            spec.loader.exec_module(module)
        else:
            importlib.import_module(name)


def training_task(spec: CellSpec, agent) -> str:
    """Where the cell's agent learns: the task itself, except that the task-aware reference learns the
    task's dense counterpart where the task declares one (`suite.register(..., reference_task=)`).
    Knowing the task leaves nothing to infer, but PPO alone would still not find a sparse reward (on
    cheetah_dir_sparse it never leaves the zone), and the reference is meant to show how well the task
    can be solved once it is known. It is deployed on the task itself like every agent."""
    dense = suite.reference_task(spec.task)
    return dense if dense is not None and reads_true_task(agent) else spec.task


def run_cell(spec: CellSpec, sync: Callable[[], None] | None = None) -> dict:
    """Trains and evaluates one cell; returns its record (also on disk). The agent is used only through
    the benchmarkable-agent protocol (evaluation/protocol.py). `sync()`, if given, is called before every
    training iteration's bookkeeping, when the files of the previous one (checkpoint included) are
    written: a Ray cell copies them to its storage there (evaluation/remote.py)."""
    import torch  # noqa: F401  (imported here so that worker processes set their own threads)
    from torch.utils.tensorboard import SummaryWriter

    if spec.physics_threads:
        # Parallel cells share the cores; the suite's batched simulators read this (results do not depend on it).
        os.environ["HYPERSTATE_PHYSICS_THREADS"] = str(spec.physics_threads)
    import_modules(spec.imports)
    directory = spec.directory
    directory.mkdir(parents=True, exist_ok=True)
    record_path = directory / grid.RECORD
    if spec.resume and record_path.exists():
        record = json.loads(record_path.read_text())
        if record.get("complete") and record["frames"] >= spec.frames:
            # Written by older code? Brought up to the current metrics from what the cell saved.
            if upgrade_record(record, directory, spec.episodes_per_task):
                write_json_atomic(record_path, record)
            return record
    agent = protocol.make_agent(spec.agent, **spec.overrides)
    record = {
        "agent": spec.agent,
        "task": spec.task,
        "seed": spec.seed,
        "frames": spec.frames,
        "trained_on": training_task(spec, agent),
        "config": protocol.describe(agent),
        "curve": [],
        "final": None,
        "versions": versions(),
        "complete": False,
    }
    if spec.resume and record_path.exists():
        record["curve"] = json.loads(record_path.read_text())["curve"]
    tasks = evaluation_tasks(spec.task, spec.eval_tasks)
    coverage = HyperStateCoverage.for_task(spec.task)  # None where the task declares no coverage grid
    coverage_path = directory / grid.COVERAGE
    if coverage is not None and spec.resume and coverage_path.exists():
        # Cells are a set: replaying iterations after the checkpoint marks the same cells again.
        coverage.visited = np.load(coverage_path)
    writer = SummaryWriter(log_dir=str(Path(spec.out) / grid.TENSORBOARD / spec.cell_id))
    started = time.perf_counter() - (record["curve"][-1]["wall_seconds"] if record["curve"] else 0.0)

    # Training-log families averaged into each curve point over the iterations since the previous one: the
    # reward streams' shares and the value heads' advantage spreads, each keyed by stream. Each iteration's
    # values also go to a log on disk (grid.POINT_LOG), from which a resumed cell restores those of the
    # iterations between the last point and its checkpoint (a periodic checkpoint falls between points).
    since_point: dict[str, dict[str, list[float]]] = {"reward_share": {}, "advantage_std": {}}
    point_log = directory / grid.POINT_LOG

    def evaluate(frames: int) -> dict:
        metrics = deployment_metrics(deploy(agent, spec.task, tasks, spec.episodes_per_task), spec.task)
        sampled = deploy(agent, spec.task, tasks, spec.episodes_per_task, deterministic=False)
        point = {
            "frames": frames,
            "online_return": metrics["online_return"],
            "online_return_stochastic": float(sampled.rewards.sum(0).mean()),
            "episode_returns": metrics["episode_returns"],
            "wall_seconds": time.perf_counter() - started,
        }
        for family, streams in since_point.items():
            if streams:
                point[family] = {stream: float(np.mean(values)) for stream, values in streams.items()}
                streams.clear()
        if coverage is not None and coverage.visited.any():
            point["coverage"] = coverage.fraction()
            writer.add_scalar("eval/hyperstate_coverage", point["coverage"], frames)
        # A point re-run after a crash (its checkpoint was not yet written) replaces the old one.
        record["curve"] = [p for p in record["curve"] if p["frames"] < frames] + [point]
        writer.add_scalar("eval/online_return", point["online_return"], frames)
        return metrics

    def due(frames: int) -> bool:
        """An evaluation point: the first report in each eval_every-frames interval, and the last one."""
        bucket = frames // spec.eval_every
        done = any(p["frames"] // spec.eval_every == bucket and p["frames"] <= frames for p in record["curve"])
        final_done = bool(record["curve"]) and record["curve"][-1]["frames"] == frames
        return (bucket >= 1 and not done) or (frames >= spec.frames and not final_done)

    last_progress = [0.0]

    def report_progress(frames: int, fps: float, complete: bool = False) -> None:
        """The cell's state for the driver's view (evaluation/progress.py); at most every 2 s."""
        now = time.perf_counter()
        if not complete and now - last_progress[0] < 2.0:
            return
        last_progress[0] = now
        wall = now - started
        point = record["curve"][-1] if record["curve"] else None
        state = {
            "frames": frames,
            "total_frames": spec.frames,
            "fps": fps,
            "wall_seconds": wall,
            "online_return": None if point is None else point["online_return"],
            "return_frames": None if point is None else point["frames"],
            "eta_seconds": None if frames <= 0 else max(0.0, (spec.frames - frames) * wall / frames),
            "complete": complete,
        }
        write_json_atomic(directory / grid.PROGRESS, state)

    replaying = [spec.resume]  # until the first iteration after a resume has been seen
    point_written = [False]  # the previous iteration wrote a curve point

    def on_iteration(log: dict) -> bool:
        if sync is not None:
            sync()
        frames = int(log["frames"])
        if replaying[0]:
            # The first iteration after the checkpoint: points at or past it were written after the checkpoint
            # (a crash between the two) and are evaluated again in place, so that each point still averages
            # its own iterations (`since_point`), as in an uninterrupted run: those after the last point
            # and up to the checkpoint come back from the log.
            record["curve"] = [p for p in record["curve"] if p["frames"] < frames]
            last_point = record["curve"][-1]["frames"] if record["curve"] else 0
            restored = [e for e in read_point_log(point_log) if last_point < e["frames"] < frames]
            for entry in restored:
                add_to_point(since_point, entry["values"])
            point_log.write_text("".join(json.dumps(e) + "\n" for e in restored))
            replaying[0] = False
        elif point_written[0]:
            # The previous iteration's point and its checkpoint are on disk: its iterations are not needed again.
            point_log.write_text("")
        point_written[0] = False
        report_progress(frames, float(log.get("fps", 0.0)), complete=False)
        values: dict[str, dict[str, float]] = {}
        for key, value in log.items():
            family, _, stream = key.partition("/")
            if family in since_point:
                values.setdefault(family, {})[stream] = value
            if isinstance(value, float) and key not in ("wall_seconds",):
                writer.add_scalar(key if "/" in key else f"train/{key}", value, frames)
        add_to_point(since_point, values)
        with point_log.open("a") as f:
            f.write(json.dumps({"frames": frames, "values": values}) + "\n")
        if coverage is not None:
            # Every iteration: a resume replays only the iterations after its checkpoint, which may fall
            # between points, so the visits of those before it must already be on disk.
            save_array_atomic(coverage_path, coverage.visited)
        if not due(frames):
            return False
        point_written[0] = True
        evaluate(frames)
        # The agent at every evaluation point, for diagnostics through training (bonus heat maps).
        snapshot = grid.snapshot_path(Path(spec.out), spec.cell_id, frames)
        snapshot.parent.mkdir(exist_ok=True)
        agent.save(snapshot)
        write_json_atomic(record_path, record)
        return True  # checkpoint now: a resumed run rejoins the curve here

    if hasattr(agent, "name"):
        agent.name = f"{spec.agent} seed {spec.seed}"
    protocol.train(
        agent,
        record["trained_on"],
        spec.frames,
        spec.seed,
        checkpoint_dir=directory,
        resume=spec.resume,
        progress=spec.progress,
        on_iteration=on_iteration,
        on_rollout=None if coverage is None else coverage.update,
    )
    record["frames"] = int(getattr(agent, "total_frames", spec.frames))
    final = deploy(agent, spec.task, tasks, spec.episodes_per_task)
    record["final"] = deployment_metrics(final, spec.task, probe=True)
    # The stochastic policy (sampled actions, fixed seed) next to the deterministic one.
    sampled = deploy(agent, spec.task, tasks, spec.episodes_per_task, deterministic=False)
    record["final"]["stochastic"] = deployment_metrics(sampled, spec.task)
    if reads_true_task(agent):
        # The reference also deployed Bayes-adaptively: an achievable lower bound on Bayes-optimal.
        record["final"]["certainty_equivalent"] = certainty_equivalent_metrics(
            agent, spec.task, tasks, spec.episodes_per_task
        )
    save_deployment(directory, final)
    agent.save(directory / grid.AGENT)
    point_log.unlink(missing_ok=True)
    record["complete"] = True
    write_json_atomic(record_path, record)
    report_progress(record["frames"], 0.0, complete=True)
    writer.close()
    return record


def save_deployment(directory: Path, deployment: Any) -> None:
    """The cell's final deterministic deployment as `deployment.npz` (what the behaviour plot draws)."""
    np.savez_compressed(
        directory / grid.DEPLOYMENT,
        rewards=deployment.rewards,
        tasks=deployment.tasks,
        inner_episode=deployment.inner_episode,
        features=deployment.features,
        **{f"obs_{k}": v for k, v in deployment.observations.items()},
    )


def add_to_point(since_point: dict[str, dict[str, list[float]]], values: dict[str, dict[str, float]]) -> None:
    """Adds one iteration's logged values ({family: {stream: value}}) to those the next point averages."""
    for family, streams in values.items():
        for stream, value in streams.items():
            since_point[family].setdefault(stream, []).append(value)


def read_point_log(path: Path) -> list[dict]:
    """The iterations in a cell's point log; a line cut short by a crash ends it."""
    entries = []
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                entries.append(json.loads(line))
            except json.JSONDecodeError:
                break
    return entries


def load_records(out: Path) -> list[dict]:
    """All cell records under `out`, in a stable order."""
    records = []
    for path in sorted((out / grid.CELLS).glob(f"*/{grid.RECORD}")):
        try:
            records.append(json.loads(path.read_text()))
        except (OSError, json.JSONDecodeError):
            continue  # a record being replaced right now; the next write catches up
    return records


def write_results(out: Path) -> None:
    """`OUT/results.json`: one record per cell (the contract), written atomically."""
    write_json_atomic(out / grid.RESULTS, load_records(out))
