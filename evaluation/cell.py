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
import json
import os
import sys
import time
from collections.abc import Callable
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

# Moved to their own modules; importable from here too until the deprecation in docs/evaluation.md runs out.
from hyperstate.evaluation.imports import import_modules, materialize_imports, read_import_sources  # noqa: F401
from hyperstate.evaluation.provenance import cpu_description, versions  # noqa: F401
from hyperstate.evaluation.upgrade import upgrade_record
from hyperstate.files import append_json_line, read_json_lines, save_array_atomic, write_json_atomic


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


def report_failure(spec: CellSpec, error: BaseException) -> str:
    """Prints one line about a failed cell to stderr and returns it."""
    line = f"{spec.cell_id}: {type(error).__name__}: {error}".splitlines()[0]
    command = cli.program_name("evaluation/run.py")
    print(f"{command}: cell failed (the others go on; --resume retries it): {line}", file=sys.stderr)
    return line


def training_task(spec: CellSpec, agent) -> str:
    """Where the cell's agent learns: the task itself, except that the task-aware reference learns the
    task's dense counterpart where the task declares one (`suite.register(..., reference_task=)`).
    Knowing the task leaves nothing to infer, but PPO alone would still not find a sparse reward (on
    cheetah_dir_sparse it never leaves the zone), and the reference is meant to show how well the task
    can be solved once it is known. It is deployed on the task itself like every agent."""
    dense = suite.reference_task(spec.task)
    return dense if dense is not None and reads_true_task(agent) else spec.task


class PointLog:
    """The training-log values the next curve point averages: per family (the reward streams' shares, the
    value heads' advantage spreads), per stream, the values of the iterations since the previous point.

    Each iteration's values also go to a file (grid.POINT_LOG), from which a resumed cell restores those of
    the iterations between its last point and its checkpoint (a periodic checkpoint falls between points),
    so that each point averages its own iterations, as in an uninterrupted run."""

    FAMILIES = ("reward_share", "advantage_std")

    def __init__(self, path: Path):
        self.path = path
        self.since_point: dict[str, dict[str, list[float]]] = {family: {} for family in self.FAMILIES}

    def add(self, values: dict[str, dict[str, float]]) -> None:
        """Adds one iteration's values ({family: {stream: value}}) to those the next point averages."""
        for family, streams in values.items():
            for stream, value in streams.items():
                self.since_point[family].setdefault(stream, []).append(value)

    def record(self, frames: int, values: dict[str, dict[str, float]]) -> None:
        """Adds one iteration's values and appends them to the file."""
        self.add(values)
        append_json_line(self.path, {"frames": frames, "values": values})

    def entries(self) -> list[dict]:
        """The iterations in the file; a line cut short by a crash ends it."""
        return read_json_lines(self.path)

    def restore(self, after: int, before: int) -> None:
        """After a resume: takes back the iterations logged between frames `after` (the last point) and
        `before` (the checkpoint), and keeps only those in the file."""
        restored = [e for e in self.entries() if after < e["frames"] < before]
        for entry in restored:
            self.add(entry["values"])
        self.path.write_text("".join(json.dumps(e) + "\n" for e in restored))

    def clear_file(self) -> None:
        """The previous point and its checkpoint are on disk: its iterations are not needed again."""
        self.path.write_text("")

    def take_averages(self) -> dict[str, dict[str, float]]:
        """{family: {stream: mean}} since the previous point, for the new point; starts the next one."""
        out = {}
        for family, streams in self.since_point.items():
            if streams:
                out[family] = {stream: float(np.mean(values)) for stream, values in streams.items()}
                streams.clear()
        return out


def read_point_log(path: Path) -> list[dict]:
    """The iterations in a cell's point log (`PointLog.entries`)."""
    return PointLog(path).entries()


def run_cell(spec: CellSpec, sync: Callable[[], None] | None = None) -> dict:
    """Trains and evaluates one cell; returns its record (also on disk). The agent is used only through
    the benchmarkable-agent protocol (evaluation/protocol.py). `sync()`, if given, is called before every
    training iteration's bookkeeping, when the files of the previous one (checkpoint included) are
    written: a Ray cell copies them to its storage there (evaluation/remote.py)."""
    import torch  # noqa: F401  (imported here so that worker processes set their own threads)

    if spec.physics_threads:
        # Parallel cells share the cores; the suite's batched simulators read this (results do not depend on it).
        os.environ["HYPERSTATE_PHYSICS_THREADS"] = str(spec.physics_threads)
    import_modules(spec.imports)
    spec.directory.mkdir(parents=True, exist_ok=True)
    record_path = spec.directory / grid.RECORD
    if spec.resume and record_path.exists():
        record = json.loads(record_path.read_text())
        if record.get("complete") and record["frames"] >= spec.frames:
            # Written by older code? Brought up to the current metrics from what the cell saved.
            if upgrade_record(record, spec.directory, spec.episodes_per_task):
                write_json_atomic(record_path, record)
            return record
    return CellRun(spec, sync).run()


class CellRun:
    """One cell's training run: its state is the attributes, its steps the methods — train to the next
    evaluation point (`on_iteration`, called by the agent after every training iteration), deploy and
    write the point (`write_point`), checkpoint (the agent does, when `on_iteration` returns True), and
    at the end deploy the final agent (`finish`)."""

    PROGRESS_EVERY = 2.0  # seconds between the progress files the driver's view reads

    def __init__(self, spec: CellSpec, sync: Callable[[], None] | None = None):
        from torch.utils.tensorboard import SummaryWriter

        self.spec, self.sync = spec, sync
        self.directory = spec.directory
        self.record_path = self.directory / grid.RECORD
        self.agent = protocol.make_agent(spec.agent, **spec.overrides)
        self.record = {
            "agent": spec.agent,
            "task": spec.task,
            "seed": spec.seed,
            "frames": spec.frames,
            "trained_on": training_task(spec, self.agent),
            "config": protocol.describe(self.agent),
            "curve": [],
            "final": None,
            "versions": versions(),
            "complete": False,
        }
        if spec.resume and self.record_path.exists():
            self.record["curve"] = json.loads(self.record_path.read_text())["curve"]
        self.tasks = evaluation_tasks(spec.task, spec.eval_tasks)
        self.coverage = HyperStateCoverage.for_task(spec.task)  # None where the task declares no coverage grid
        self.coverage_path = self.directory / grid.COVERAGE
        if self.coverage is not None and spec.resume and self.coverage_path.exists():
            # Cells are a set: replaying iterations after the checkpoint marks the same cells again.
            self.coverage.visited = np.load(self.coverage_path)
        self.writer = SummaryWriter(log_dir=str(Path(spec.out) / grid.TENSORBOARD / spec.cell_id))
        curve = self.record["curve"]
        self.started = time.perf_counter() - (curve[-1]["wall_seconds"] if curve else 0.0)
        self.point_log = PointLog(self.directory / grid.POINT_LOG)
        self.last_progress = 0.0
        self.replaying = spec.resume  # until the first iteration after a resume has been seen
        self.point_written = False  # the previous iteration wrote a curve point

    def run(self) -> dict:
        spec = self.spec
        if hasattr(self.agent, "name"):
            self.agent.name = f"{spec.agent} seed {spec.seed}"
        protocol.train(
            self.agent,
            self.record["trained_on"],
            spec.frames,
            spec.seed,
            checkpoint_dir=self.directory,
            resume=spec.resume,
            progress=spec.progress,
            on_iteration=self.on_iteration,
            on_rollout=None if self.coverage is None else self.coverage.update,
        )
        return self.finish()

    # Training iterations ---------------------------------------------------------------------------
    def on_iteration(self, log: dict) -> bool:
        """After every training iteration: log it; at an evaluation point deploy and write the point.
        Returns whether the agent should checkpoint now (a resumed run rejoins the curve there)."""
        if self.sync is not None:
            self.sync()
        frames = int(log["frames"])
        if self.replaying:
            self.rejoin_curve(frames)
        elif self.point_written:
            self.point_log.clear_file()
        self.point_written = False
        self.report_progress(frames, float(log.get("fps", 0.0)))
        self.log_iteration(frames, log)
        if not self.due(frames):
            return False
        self.point_written = True
        self.write_point(frames)
        return True

    def rejoin_curve(self, frames: int) -> None:
        """The first iteration after the checkpoint: points at or past it were written after the checkpoint
        (a crash between the two) and are evaluated again in place, so that each point still averages its
        own iterations, as in an uninterrupted run: those after the last point and up to the checkpoint
        come back from the point log."""
        self.record["curve"] = [p for p in self.record["curve"] if p["frames"] < frames]
        last_point = self.record["curve"][-1]["frames"] if self.record["curve"] else 0
        self.point_log.restore(last_point, frames)
        self.replaying = False

    def log_iteration(self, frames: int, log: dict) -> None:
        """The iteration's scalars to tensorboard, its averaged families to the point log, and the
        coverage to disk."""
        values: dict[str, dict[str, float]] = {}
        for key, value in log.items():
            family, _, stream = key.partition("/")
            if family in PointLog.FAMILIES:
                values.setdefault(family, {})[stream] = value
            if isinstance(value, float) and key not in ("wall_seconds",):
                self.writer.add_scalar(key if "/" in key else f"train/{key}", value, frames)
        self.point_log.record(frames, values)
        if self.coverage is not None:
            # Every iteration: a resume replays only the iterations after its checkpoint, which may fall
            # between points, so the visits of those before it must already be on disk.
            save_array_atomic(self.coverage_path, self.coverage.visited)

    def due(self, frames: int) -> bool:
        """An evaluation point: the first report in each eval_every-frames interval, and the last one."""
        spec, curve = self.spec, self.record["curve"]
        bucket = frames // spec.eval_every
        done = any(p["frames"] // spec.eval_every == bucket and p["frames"] <= frames for p in curve)
        final_done = bool(curve) and curve[-1]["frames"] == frames
        return (bucket >= 1 and not done) or (frames >= spec.frames and not final_done)

    def write_point(self, frames: int) -> None:
        """Deploys the agent, adds the curve point, saves the agent's snapshot and the record."""
        self.evaluate(frames)
        # The agent at every evaluation point, for diagnostics through training (bonus heat maps).
        snapshot = grid.snapshot_path(Path(self.spec.out), self.spec.cell_id, frames)
        snapshot.parent.mkdir(exist_ok=True)
        self.agent.save(snapshot)
        write_json_atomic(self.record_path, self.record)

    def evaluate(self, frames: int) -> dict:
        """One curve point: deterministic and sampled deployments on the held-out tasks."""
        spec = self.spec
        metrics = deployment_metrics(deploy(self.agent, spec.task, self.tasks, spec.episodes_per_task), spec.task)
        sampled = deploy(self.agent, spec.task, self.tasks, spec.episodes_per_task, deterministic=False)
        point = {
            "frames": frames,
            "online_return": metrics["online_return"],
            "online_return_stochastic": float(sampled.rewards.sum(0).mean()),
            "episode_returns": metrics["episode_returns"],
            "wall_seconds": time.perf_counter() - self.started,
        }
        point.update(self.point_log.take_averages())
        if self.coverage is not None and self.coverage.visited.any():
            point["coverage"] = self.coverage.fraction()
            self.writer.add_scalar("eval/hyperstate_coverage", point["coverage"], frames)
        # A point re-run after a crash (its checkpoint was not yet written) replaces the old one.
        self.record["curve"] = [p for p in self.record["curve"] if p["frames"] < frames] + [point]
        self.writer.add_scalar("eval/online_return", point["online_return"], frames)
        return metrics

    def report_progress(self, frames: int, fps: float, complete: bool = False) -> None:
        """The cell's state for the driver's view (evaluation/progress.py); at most every 2 s."""
        now = time.perf_counter()
        if not complete and now - self.last_progress < self.PROGRESS_EVERY:
            return
        self.last_progress = now
        wall, total = now - self.started, self.spec.frames
        point = self.record["curve"][-1] if self.record["curve"] else None
        state = {
            "frames": frames,
            "total_frames": total,
            "fps": fps,
            "wall_seconds": wall,
            "online_return": None if point is None else point["online_return"],
            "return_frames": None if point is None else point["frames"],
            "eta_seconds": None if frames <= 0 else max(0.0, (total - frames) * wall / frames),
            "complete": complete,
        }
        write_json_atomic(self.directory / grid.PROGRESS, state)

    # The end ---------------------------------------------------------------------------------------
    def finish(self) -> dict:
        """Deploys the final agent (deterministic, sampled, and Bayes-adaptively for the reference), saves
        it and its deployment, and completes the record."""
        spec, agent, record = self.spec, self.agent, self.record
        record["frames"] = int(getattr(agent, "total_frames", spec.frames))
        final = deploy(agent, spec.task, self.tasks, spec.episodes_per_task)
        record["final"] = deployment_metrics(final, spec.task, probe=True)
        # The stochastic policy (sampled actions, fixed seed) next to the deterministic one.
        sampled = deploy(agent, spec.task, self.tasks, spec.episodes_per_task, deterministic=False)
        record["final"]["stochastic"] = deployment_metrics(sampled, spec.task)
        if reads_true_task(agent):
            # The reference also deployed Bayes-adaptively: an achievable lower bound on Bayes-optimal.
            record["final"]["certainty_equivalent"] = certainty_equivalent_metrics(
                agent, spec.task, self.tasks, spec.episodes_per_task
            )
        save_deployment(self.directory, final)
        agent.save(self.directory / grid.AGENT)
        self.point_log.path.unlink(missing_ok=True)
        record["complete"] = True
        write_json_atomic(self.record_path, record)
        self.report_progress(record["frames"], 0.0, complete=True)
        self.writer.close()
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


def load_records(out: Path) -> list[dict]:
    """All cell records under `out`, in a stable order."""
    records = []
    for path in sorted((out / grid.CELLS).glob(f"*/{grid.RECORD}")):
        try:
            records.append(json.loads(path.read_text()))
        except (OSError, json.JSONDecodeError):
            continue  # a record being replaced right now; the next write catches up
    return records


def record_progress(record: dict) -> dict:
    """Where a cell stands, finished or not: agent, task, seed, complete, the last evaluation point's frames
    and wall seconds (0 and None before the first), the online return at every point, and the final
    deployment's entry (empty before it)."""
    curve = record.get("curve") or []
    return {
        "agent": record["agent"],
        "task": record.get("task"),
        "seed": record["seed"],
        "complete": bool(record.get("complete")),
        "frames": curve[-1]["frames"] if curve else 0,
        "wall_seconds": curve[-1].get("wall_seconds") if curve else None,
        "curve": [point["online_return"] for point in curve],
        "final": record.get("final") or {},
    }


def write_results(out: Path) -> None:
    """`OUT/results.json`: one record per cell (the contract), written atomically."""
    write_json_atomic(out / grid.RESULTS, load_records(out))
