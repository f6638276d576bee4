"""Train and evaluate a grid of agents × tasks × seeds; report online return at deployment.

    python evaluation/run.py --agents oracle oracle_rh --tasks cheetah_dir_sparse --seeds 0 1 2 \\
        --frames 2000000 --out runs/fig2

Writes OUT/results.json (one record per agent × task × seed: config, learning curve, final deployment
metrics, versions), OUT/summary.csv (mean, IQM and 95 % bootstrap CI over seeds; regret against the
task-aware reference), OUT/figures/*.png (learning curves with CI bands, behaviour plots) and
OUT/tb/ (tensorboard scalars). Every cell writes its record atomically after each evaluation point and
checkpoints there; after a crash, the same command with --resume finishes the grid.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

# Nothing here renders: name no OpenGL backend and dm_control would try GLFW and warn about DISPLAY.
os.environ.setdefault("MUJOCO_GL", "disable")

from hyperstate import agents, suite
from hyperstate.evaluation import cli, provenance
from hyperstate.evaluation import grid as grid_layout
from hyperstate.evaluation.cell import CellSpec, load_records, report_failure, run_cell, write_results
from hyperstate.evaluation.cli import UsageError
from hyperstate.evaluation.grid_setup import (  # noqa: F401  (build_grid, check_tasks, read_json_file: also imported from here)
    build_grid,
    check_tasks,
    incompatible_cells,
    load_config_file,
    prepare_out,
    read_json_file,
)
from hyperstate.evaluation.imports import import_modules, read_import_sources
from hyperstate.evaluation.progress import POLL_SECONDS, RESULTS_EVERY_SECONDS, GridProgress
from hyperstate.evaluation.report import REFERENCE_AGENT, text_table, write_figures, write_summary


def program_name() -> str:
    """`hyperstate-run` or `evaluation/run.py`, as the user typed it."""
    return cli.program_name("evaluation/run.py")


_SUFFIXES = {"k": 10**3, "m": 10**6, "g": 10**9}


def frame_count(text: str) -> int:
    """A whole number of frames: `20000000`, `2e7`, `20M`, `1.5M`, `500k` (argparse type)."""
    value = text.strip().replace("_", "")
    scale = _SUFFIXES.get(value[-1:].lower(), 1)
    number = value[:-1] if scale > 1 else value
    try:
        if scale == 1 and number.lstrip("+-").isdigit():
            return int(number)
        amount = float(number) * scale
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of frames (e.g. 20000000, 2e7, 20M)") from None
    if not amount.is_integer() or abs(amount) > 1e15:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of frames")
    return int(amount)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = cli.OneLineParser(
        prog=program_name(), description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--agents",
        nargs="+",
        metavar="A",
        help=f"agents: presets ({', '.join(agents.list_presets())}) or agents registered by --import modules",
    )
    p.add_argument(
        "--tasks",
        nargs="+",
        metavar="T",
        help=f"tasks: {', '.join(suite.TASKS)} (with --deploy: default, each saved cell's own)",
    )
    p.add_argument("--seeds", nargs="+", type=int, default=[0], metavar="S", help="training seeds (default: 0)")
    p.add_argument(
        "--frames",
        type=frame_count,
        help="environment steps of training per cell (20000000, 2e7 or 20M); with --resume, a larger budget "
        "than the grid's extends every cell to it",
    )
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument(
        "--eval-every",
        type=frame_count,
        default=None,
        metavar="F",
        help="frames between evaluation points (default: frames / 10, rounded to iterations)",
    )
    p.add_argument(
        "--eval-tasks",
        type=int,
        default=20,
        metavar="M",
        help="held-out tasks per evaluation (finite priors: every support point is covered)",
    )
    p.add_argument(
        "--episodes-per-task",
        type=int,
        default=None,
        metavar="K",
        help="BAMDP horizon (MDP episodes) at deployment (default: the task's)",
    )
    p.add_argument(
        "--config",
        type=Path,
        nargs="+",
        default=[],
        metavar="FILE",
        help="TOML or YAML overrides: a table per agent name, and/or 'all' for every agent, "
        'mapping dotted config fields to values (e.g. [all] "ppo.num_envs" = 32); with several files, '
        "later ones override earlier ones key by key (a base file plus one change per experiment)",
    )
    p.add_argument(
        "--import",
        dest="imports",
        nargs="+",
        default=[],
        metavar="MODULE",
        help="modules or .py files to import first, e.g. your own tasks registered with suite.register "
        "(imported in every worker too; Ray cells import the driver's copy of each .py file)",
    )
    p.add_argument(
        "--no-reference",
        action="store_true",
        help=f"do not train the task-aware reference ({REFERENCE_AGENT}) used for regret",
    )
    p.add_argument(
        "--video",
        action="store_true",
        help="render one deployment per agent and task (first seed) to OUT/videos/*.mp4 "
        "(needs MUJOCO_GL=egl or osmesa support; see evaluation/video.py)",
    )
    p.add_argument(
        "--video-tasks",
        type=int,
        default=1,
        metavar="N",
        help="with --video: deployments per video, on the first N held-out tasks (default 1)",
    )
    p.add_argument(
        "--no-diagnostics",
        action="store_true",
        help="skip the bonus-landscape figures (evaluation/diagnostics.py) drawn for agents with an RND bonus",
    )
    p.add_argument(
        "--deploy",
        nargs="+",
        type=Path,
        default=None,
        metavar="PATH",
        help="deploy saved agents instead of training: cell folders (agent.pt + record.json, e.g. zoo/*) or "
        "agent.pt files; writes one cell each and the report (no --agents, no --frames)",
    )
    p.add_argument("--resume", action="store_true", help="continue a grid in OUT (completed cells are kept)")
    p.add_argument("--force", action="store_true", help="delete OUT's previous results first")
    p.add_argument(
        "--executor",
        choices=["local", "ray"],
        default="local",
        help="local: a process pool on this machine; ray: one Ray task per cell",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="W",
        help="parallel cells (local executor; default: 1 per 2 cores, at least 1)",
    )
    p.add_argument(
        "--physics-threads",
        type=int,
        default=None,
        metavar="N",
        help="physics threads per cell (default: the cores shared out among the workers); results do not depend on it",
    )
    p.add_argument(
        "--ray-address", default=None, help="Ray cluster address (default: $RAY_ADDRESS, else a local instance)"
    )
    p.add_argument(
        "--storage",
        default=None,
        metavar="URI",
        help="ray: where cells keep checkpoints, reachable from every node: a path or an fsspec URI such as "
        "s3://bucket/prefix (default: OUT, for one machine or a shared filesystem)",
    )
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress view (on a terminal: a live bar per running cell; elsewhere: a line per running cell "
        "every minute and one per finished cell)",
    )
    return p.parse_args(argv)


def run_local(specs: list[CellSpec], workers: int, progress: bool, out: Path) -> list[str]:
    """Runs the cells (in a thread for one worker, else in spawned processes) while the driver keeps the
    grid-level files and the progress view; returns one line per failed cell (a failure stops no other)."""
    import concurrent.futures
    import multiprocessing

    failures = []
    view = GridProgress(out, [s.cell_id for s in specs], enabled=progress)
    if workers == 1:
        executor = concurrent.futures.ThreadPoolExecutor(1)
    else:
        executor = concurrent.futures.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))
    with executor as pool:
        pending = {pool.submit(run_cell, s): s for s in specs}
        last_results = time.monotonic()
        while pending:
            done, _ = concurrent.futures.wait(
                pending, timeout=POLL_SECONDS, return_when=concurrent.futures.FIRST_COMPLETED
            )
            view.poll()
            if done or time.monotonic() - last_results >= RESULTS_EVERY_SECONDS:
                write_results(out)  # the driver is the only writer of the grid-level files
                last_results = time.monotonic()
            for future in done:
                spec = pending.pop(future)
                try:
                    future.result()
                    view.cell_done(spec.cell_id)
                except Exception as e:  # noqa: BLE001  (reported, and the grid goes on)
                    failures.append(report_failure(spec, e))
                    view.cell_done(spec.cell_id, failed=True)
    view.close()
    return failures


def write_diagnostics(out: Path, records: list[dict]) -> None:
    """The bonus landscape through training for every finished cell whose agent has an RND bonus."""
    from hyperstate.evaluation.diagnostics import cell_diagnostics

    for record in records:
        if not record.get("complete"):
            continue
        cell = grid_layout.record_cell_id(record)
        try:
            cell_diagnostics(out, cell)
        except Exception as e:  # noqa: BLE001  (a figure must not cost the results)
            print(f"{program_name()}: bonus landscape of {cell} failed: {type(e).__name__}: {e}", file=sys.stderr)


def render_videos(args: argparse.Namespace) -> None:
    """Runs evaluation/video.py in a fresh process: MUJOCO_GL is read when dm_control is imported, and
    training ran without rendering."""
    gl = os.environ.get("MUJOCO_GL")
    env = {**os.environ, "MUJOCO_GL": gl if gl in ("egl", "osmesa", "glfw") else "egl"}
    command = [sys.executable, "-m", "hyperstate.evaluation.video", str(args.out), "--tasks", str(args.video_tasks)]
    if args.imports:
        command += ["--import", *args.imports]
    result = subprocess.run(command, env=env, cwd=Path(__file__).resolve().parents[1])
    if result.returncode != 0:
        print(
            f"{program_name()}: rendering the videos failed (exit {result.returncode}); the results stand",
            file=sys.stderr,
        )


def deploy_main(args: argparse.Namespace) -> int:
    """--deploy: saved agents deployed on their tasks, no training."""
    from hyperstate.evaluation.saved import SavedAgentError, deploy_saved, summary_lines

    if args.agents or args.frames is not None or args.resume:
        raise UsageError("--deploy takes saved agents: no --agents, --frames or --resume")
    check_tasks(args.tasks or [])
    if args.out.exists() and any(args.out.iterdir()):
        if not args.force:
            raise UsageError(f"--out {args.out} is not empty; pass --force to overwrite it")
        shutil.rmtree(args.out)
    try:
        import_modules(args.imports)
        records = deploy_saved(args.deploy, args.out, args.tasks, args.eval_tasks, args.episodes_per_task)
    except SavedAgentError as e:
        raise UsageError(str(e)) from None
    write_results(args.out)
    rows = write_summary(args.out, records)
    write_figures(args.out, records)
    print(*summary_lines(records), sep="\n")
    print()
    print(text_table(rows))
    print(f"\n{len(records)} deployments; results and figures in {args.out}/")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.deploy:
        try:
            return deploy_main(args)
        except UsageError as e:
            print(f"{program_name()}: error: {e}", file=sys.stderr)
            return 2
    try:
        if not args.agents or not args.tasks or args.frames is None:
            raise UsageError("--agents, --tasks and --frames are required (or --deploy saved agents)")
        names, overrides = build_grid(args)
        eval_every = args.eval_every or max(1, args.frames // 10)
        grid = {
            "agents": names,
            "tasks": args.tasks,
            "seeds": args.seeds,
            "frames": args.frames,
            "eval_every": eval_every,
            "eval_tasks": args.eval_tasks,
            "episodes_per_task": args.episodes_per_task,
            "overrides": overrides,
        }
        prepare_out(args, grid)
    except UsageError as e:
        print(f"{program_name()}: error: {e}", file=sys.stderr)
        return 2
    skipped = incompatible_cells(args, names, overrides)
    for (name, task), reason in skipped.items():
        print(f"{program_name()}: skipping {name} on {task}: {reason}", file=sys.stderr)
    if len(skipped) == len(names) * len(args.tasks):
        print(f"{program_name()}: error: no agent of the grid can run on its tasks", file=sys.stderr)
        return 2
    workers = args.workers or max(1, (os.cpu_count() or 1) // 2)
    specs = cell_specs(args, names, overrides, skipped, eval_every, workers)
    commands = args.out / grid_layout.COMMANDS
    invocation = provenance.record_start(commands, [program_name(), *(sys.argv[1:] if argv is None else argv)])
    started = time.perf_counter()
    try:
        if args.executor == "ray":
            try:
                import ray  # noqa: F401
            except ImportError:
                raise UsageError("--executor ray needs Ray: pip install '.[ray]'") from None
            from hyperstate.evaluation.remote import run_ray

            failures = run_ray(specs, args.ray_address, not args.no_progress, args.out)
        else:
            failures = run_local(specs, workers, not args.no_progress, args.out)
    except UsageError as e:
        print(f"{program_name()}: error: {e}", file=sys.stderr)
        return 2
    records, rows = report(args)
    wall_seconds = time.perf_counter() - started
    provenance.record_end(commands, invocation, wall_seconds, len(failures))
    print()
    print(text_table(rows))
    print(f"\n{len(records)} cells in {wall_seconds:.0f} s; results in {args.out}/")
    if failures:
        print(f"{program_name()}: {len(failures)} cell(s) failed:", *failures, sep="\n  ", file=sys.stderr)
        return 1
    return 0


def cell_specs(
    args: argparse.Namespace, names: list[str], overrides: dict, skipped: dict, eval_every: int, workers: int
) -> list[CellSpec]:
    """One `CellSpec` per runnable (agent, task, seed), tasks outermost."""
    # Parallel local cells share the cores; --physics-threads overrides the share.
    physics_threads = args.physics_threads or 0
    if not physics_threads and args.executor == "local" and workers > 1:
        physics_threads = max(1, (os.cpu_count() or 1) // workers)
    cells = [(n, t, s) for t in args.tasks for n in names for s in args.seeds if (n, t) not in skipped]
    return [
        CellSpec(
            name,
            task,
            seed,
            args.frames,
            eval_every,
            args.eval_tasks,
            args.episodes_per_task,
            dict(overrides[name]),
            str(args.out),
            args.resume,
            False,  # cells draw nothing: the driver's GridProgress shows them all
            i + 1,
            tuple(args.imports),
            # Parallel cells share the cores: each cell's physics gets its share.
            physics_threads=physics_threads,
            storage=str(args.storage or args.out),
            # Ray cells may run where the user's files are not: they take the driver's copies along.
            import_sources=read_import_sources(args.imports) if args.executor == "ray" else (),
        )
        for i, (name, task, seed) in enumerate(cells)
    ]


def report(args: argparse.Namespace) -> tuple[list[dict], list[dict]]:
    """The grid-level files from every cell on disk: results.json, summary.csv, figures, diagnostics and
    videos as asked; returns the records and the summary rows."""
    write_results(args.out)
    records = load_records(args.out)
    rows = write_summary(args.out, records)
    write_figures(args.out, records)
    if not args.no_diagnostics:
        write_diagnostics(args.out, records)
    if args.video:
        render_videos(args)
    return records, rows


if __name__ == "__main__":
    sys.exit(main())
