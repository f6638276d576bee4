"""The grid on a Ray cluster, shared filesystem or not (`evaluation/run.py --executor ray`).

Each cell is one Ray task. It works in a folder of its own node, copies its checkpoint, record and
snapshots to `--storage` as it goes (evaluation/storage.py), and returns its record and files (the final
agent, deployment, snapshots, tensorboard scalars; not the checkpoint) to the driver through Ray's object
store: the driver alone writes `--out`, whatever node ran the cell. A cell whose node dies is retried by
Ray (`RETRIES` times) on another node, where it resumes from the storage's last checkpoint: the result
equals an uninterrupted run's. Cells report progress to a small actor the driver reads for its view.

On a cluster: `ray start --head` on one machine, `ray start --address HEAD:6379` on the others (each with
this package installed; `--import` .py files travel with the cells, read by the driver), then
`evaluation/run.py ... --executor ray --ray-address HEAD:6379 --storage s3://bucket/prefix` (any fsspec
URI or a path every node mounts; by default `--out`, right where all nodes share one filesystem).
Without `--ray-address` (or `$RAY_ADDRESS`) Ray starts a local instance bound to loopback.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

from hyperstate.evaluation import grid
from hyperstate.evaluation.cell import CellSpec, report_failure, run_cell, write_results
from hyperstate.evaluation.imports import materialize_imports
from hyperstate.evaluation.progress import POLL_SECONDS, RESULTS_EVERY_SECONDS, GridProgress
from hyperstate.evaluation.storage import CHECKPOINT, CellStore
from hyperstate.files import write_bytes_atomic, write_json_atomic

RETRIES = 3  # attempts after a node or worker dies (Ray's system-failure retries); errors are not retried


def run_cell_remotely(spec: CellSpec, board=None) -> tuple[dict, dict[str, bytes]]:
    """Runs one cell in a fresh folder of this node, mirrored to `spec.storage`; returns its record and
    its files ({path relative to --out: bytes}) for the driver to write."""
    workdir = Path(tempfile.mkdtemp(prefix=f"hyperstate-{spec.cell_id}-"))
    try:
        store = CellStore(spec.storage, spec.cell_id)
        pulled = store.pull(workdir)
        # The driver starts a grid only on an empty storage unless --resume: a stored record is this
        # grid's, left by an earlier attempt of this cell (its node died), so resume from it.
        resume = spec.resume or any(path.endswith(grid.RECORD) for path in pulled)
        imports = materialize_imports(spec.imports, spec.import_sources)  # the driver's files, not this node's
        local = dataclasses.replace(spec, out=str(workdir), resume=resume, imports=imports)
        progress_file = grid.cell_dir(workdir, spec.cell_id) / grid.PROGRESS
        reported = [0]

        def sync() -> None:
            store.push(workdir, skip=(grid.PROGRESS,))
            if board is not None and progress_file.exists() and progress_file.stat().st_mtime_ns != reported[0]:
                reported[0] = progress_file.stat().st_mtime_ns
                board.report.remote(spec.cell_id, json.loads(progress_file.read_text()))

        record = run_cell(local, sync=sync)
        store.push(workdir)  # everything, the final progress included (the driver gets it with the files)
        files = {
            str(path.relative_to(workdir)): path.read_bytes()
            for path in store.local_files(workdir)
            if path.name != CHECKPOINT  # only a resumed run needs it; it stays in the storage
        }
        return record, files
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


def write_cell_files(out: Path, files: dict[str, bytes]) -> None:
    """Writes a cell's returned files under `out` (paths must stay inside it)."""
    root = Path(out).resolve()
    for relative, data in files.items():
        path = (root / relative).resolve()
        if root not in path.parents:
            raise ValueError(f"a cell returned a file outside --out: {relative!r}")
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(path, data)


class ProgressBoard:
    """The latest progress state of every cell (a Ray actor): cells report, the driver reads."""

    def __init__(self) -> None:
        self._states: dict[str, dict] = {}

    def report(self, cell: str, state: dict) -> None:
        self._states[cell] = state

    def states(self) -> dict[str, dict]:
        return self._states


def run_ray(specs: list[CellSpec], address: str | None, progress: bool, out: Path) -> list[str]:
    """Runs the cells as Ray tasks (retried on node failure); the driver writes every returned cell into
    `out`, the grid-level files, and the progress view. Returns one line per failed cell."""
    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    address = address or os.environ.get("RAY_ADDRESS")
    options: dict = {"ignore_reinit_error": True, "log_to_driver": False}
    if address is None:  # a local instance, reachable from this machine only
        options.update(_node_ip_address="127.0.0.1", include_dashboard=False)
    ray.init(address=address, **options)
    here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=True)
    board = ray.remote(num_cpus=0, max_restarts=-1)(ProgressBoard).options(scheduling_strategy=here).remote()
    remote = ray.remote(num_cpus=1, max_retries=RETRIES)(run_cell_remotely)
    spec_of = {remote.remote(spec, board): spec for spec in specs}
    pending = list(spec_of)
    failures: list[str] = []
    view = GridProgress(out, [s.cell_id for s in specs], enabled=progress)
    last_results = time.monotonic()
    finished: set[str] = set()
    while pending:
        done, pending = ray.wait(pending, num_returns=1, timeout=POLL_SECONDS)
        _show_progress(ray, board, out, finished)
        view.poll()
        for ref in done:
            spec = spec_of[ref]
            finished.add(spec.cell_id)
            try:
                _, files = ray.get(ref)
                write_cell_files(out, files)
                view.cell_done(spec.cell_id)
            except Exception as e:  # noqa: BLE001  (reported, and the grid goes on)
                failures.append(report_failure(spec, e))
                view.cell_done(spec.cell_id, failed=True)
        if done or time.monotonic() - last_results >= RESULTS_EVERY_SECONDS:
            write_results(out)  # the driver is the only writer of the grid-level files
            last_results = time.monotonic()
    view.close()
    return failures


def _show_progress(ray, board, out: Path, finished: set[str]) -> None:
    """Copies the running cells' reported progress into `out` for the view (evaluation/progress.py)."""
    try:
        states = ray.get(board.states.remote(), timeout=POLL_SECONDS)
    except Exception:  # noqa: BLE001  (the board's node died: it restarts empty; the view waits)
        return
    for cell, state in states.items():
        if cell in finished:
            continue  # its final progress came with its files
        path = grid.cell_dir(out, cell) / grid.PROGRESS
        path.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(path, state)
