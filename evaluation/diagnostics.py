"""Why an agent explores the way it does: the hyper-state bonus landscape through training (Figure 1).

For a finished cell with a hyper-state (or state) RND bonus, this evaluates the bonus r(x, b) along the
position axis the task declares (`suite.register(..., position_axis=suite.PositionAxis(...))`, a
one-number position x) for each belief value the agent holds on held-out tasks: the prior (the first step
of a deployment) and the belief at the end of a deployment on each task (e.g. "forward revealed",
"backward revealed"). It does
so for the agent at every evaluation point (`snapshots/`), and for the final agent along its own
deployments, where the belief changes step by step:

    python -m hyperstate.evaluation.diagnostics OUT [--cells AGENT__TASK__sSEED ...] [--import MODULE ...]

writes `OUT/figures/bonus_<cell>.png` and the numbers behind it, `OUT/cells/<cell>/bonus_landscape.npz`.
The top row shows, per belief value, the bonus over x (columns) at each checkpoint (rows); the bottom
row the bonus over (step, x) under the belief the agent had at that step of a deployment, with the
deployment's x(t) drawn on top. Colours are log10 of each checkpoint's values divided by that checkpoint's
largest value (the agent sees the bonus divided by a running std anyway), over 4 decades: they compare
places, not checkpoints, and show gradients of orders of magnitude.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from hyperstate import suite
from hyperstate.evaluation import grid, protocol
from hyperstate.evaluation.deploy import Deployment, deploy, evaluation_tasks

# Positions at which the bonus is evaluated, as a multiple of the farthest position deployments reach.
GRID_POINTS = 121


def position_axis(task: str) -> suite.PositionAxis | None:
    """The position axis the task declares, if its observation is one number; else None."""
    axis = suite.position_axis(task)
    if axis is None:
        return None
    spec = suite.load(task, seed=0).observation_spec()
    return axis if axis.key in spec and int(np.prod(spec[axis.key].shape)) == 1 else None


def belief_values(deployment: Deployment) -> tuple[list[str], np.ndarray]:
    """Labels and features of the belief values to draw: the prior (first step) and the belief at the
    end of the deployment on each task."""
    labels = ["prior"] + [f"end of task {np.round(t, 2).tolist()}" for t in deployment.tasks]
    features = np.concatenate([deployment.features[0, :1], deployment.features[-1]])
    return labels, features


def landscape(agent: Any, template: dict[str, np.ndarray], key: str, xs: np.ndarray, features: np.ndarray) -> dict:
    """{bonus name: (len(features), len(xs)) bonus values} at position xs under each belief feature row,
    the rest of the observation taken from `template` (one observation)."""
    rows, cols = len(features), len(xs)
    obs = {k: np.repeat(np.asarray(v)[:1], rows * cols, axis=0) for k, v in template.items()}
    obs[key] = np.tile(xs, rows).reshape(-1, 1).astype(obs[key].dtype)
    values = agent.bonus_values(obs, np.repeat(features, cols, axis=0))
    return {name: v.reshape(rows, cols) for name, v in values.items()}


def along_deployment(agent: Any, deployment: Deployment, key: str, xs: np.ndarray) -> dict:
    """{bonus name: (M, T, len(xs))}: the bonus over x under the belief each deployment had at each step."""
    steps, m = deployment.rewards.shape
    template = {k: v[0, :1] for k, v in deployment.observations.items()}
    out: dict[str, list] = {}
    for i in range(m):
        for name, v in landscape(agent, template, key, xs, deployment.features[:, i]).items():
            out.setdefault(name, []).append(v)
    return {name: np.stack(v) for name, v in out.items()}


# Colours span this many decades below each checkpoint's largest bonus: the bonus varies over orders of
# magnitude (near zero where the agent has been, large far out), and a linear scale hides the gradient
# along the way from one to the other.
DECADES = 4


def _normalised(values: np.ndarray) -> np.ndarray:
    """log10 of the values divided by the largest over every axis but the first (one checkpoint's values),
    floored at -DECADES."""
    top = values.reshape(len(values), -1).max(axis=1)
    ratio = values / np.where(top > 0, top, 1.0).reshape(-1, *([1] * (values.ndim - 1)))
    return np.log10(np.maximum(ratio, 10.0**-DECADES))


def cell_diagnostics(out: Path, cell: str, tasks_per_value: int = 1) -> Path | None:
    """Computes and draws one cell's bonus landscape; returns the figure's path, or None where the cell
    has no evaluable bonus, no snapshots, or no one-number position."""
    directory = grid.cell_dir(out, cell)
    snapshots = grid.snapshots(out, cell)
    if not snapshots:
        return None
    # A cell still training has no agent.pt yet: its latest snapshot stands in for the final agent.
    final_path = directory / grid.AGENT if (directory / grid.AGENT).exists() else snapshots[-1][1]
    name, task, _ = grid.parse_cell_id(cell)
    final = protocol.load_agent(name, final_path)
    if not (hasattr(final, "bonus_values") and hasattr(final, "belief_features")):
        return None  # not an agent of bonus components: nothing to draw
    axis = position_axis(task)
    if axis is None or not final.bonus_values(*_probe_input(final, task)):
        return None
    key = axis.key
    support = suite.task_prior(task).support()
    held_out = evaluation_tasks(task, max(2, 0 if support is None else len(support)) * tasks_per_value)
    final_run = deploy(final, task, held_out)
    checkpoints = [(frames, protocol.load_agent(name, path)) for frames, path in snapshots]
    runs = [deploy(agent, task, held_out) for _, agent in checkpoints]
    # Wide enough for every position any checkpoint's deployments reached, and twice the declared region.
    reach = max(float(np.abs(run.observations[key]).max()) for run in [final_run, *runs])
    region = max(np.abs(axis.region)) if axis.region else 0.0
    half_width = max(2.0 * region, 1.1 * reach, 1.0)
    xs = np.linspace(-half_width, half_width, GRID_POINTS)
    frames, per_checkpoint, labels = [], [], None
    for (frame, agent), run in zip(checkpoints, runs, strict=True):
        labels, features = belief_values(run)
        template = {k: v[0, :1] for k, v in run.observations.items()}
        per_checkpoint.append(landscape(agent, template, key, xs, features))
        frames.append(frame)
    names = sorted(per_checkpoint[0])
    through_training = {n: np.stack([c[n] for c in per_checkpoint]) for n in names}  # (C, V, X)
    along = along_deployment(final, final_run, key, xs)  # (M, T, X)
    np.savez_compressed(
        directory / "bonus_landscape.npz",
        xs=xs,
        frames=np.array(frames),
        belief_labels=np.array(labels),
        deployment_x=final_run.observations[key][..., 0],
        deployment_tasks=final_run.tasks,
        **{f"training_{n}": v for n, v in through_training.items()},
        **{f"deployment_{n}": v for n, v in along.items()},
    )
    return _draw(out, cell, names, xs, np.array(frames), labels, through_training, along, final_run, axis)


def _probe_input(agent: Any, task: str) -> tuple[dict, np.ndarray]:
    env = suite.batch(task, 1, seed=0, privileged=True, num_threads=1)
    obs = env.reset().observation
    _, state = agent.act(obs)
    return obs, agent.belief_features(state)


def _draw(out, cell, names, xs, frames, labels, through_training, along, run, axis) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n_values, n_runs = len(labels), along[names[0]].shape[0]
    columns = max(n_values, n_runs)
    fig, axes = plt.subplots(
        2 * len(names), columns, figsize=(3.8 * columns, 6.4 * len(names)), squeeze=False, layout="constrained"
    )
    for b, name in enumerate(names):
        training = _normalised(through_training[name])  # per checkpoint, across belief values
        for v in range(columns):
            ax = axes[2 * b, v]
            if v >= n_values:
                ax.axis("off")
                continue
            image = ax.imshow(
                training[:, v],
                aspect="auto",
                origin="lower",
                cmap="viridis",
                vmin=-DECADES,
                vmax=0,
                extent=(xs[0], xs[-1], frames[0] / 1e6, frames[-1] / 1e6),
            )
            ax.set_title(f"{name}\nbelief: {labels[v]}", fontsize=8)
            ax.set_xlabel(axis.label)
            ax.set_ylabel("training frames (M)")
            for border in axis.region or ():
                ax.axvline(border, color="w", linestyle="--", linewidth=0.8)
        fig.colorbar(image, ax=axes[2 * b, n_values - 1], label="log10(bonus / checkpoint max)")
        deployment = _normalised(along[name][None])[0]  # the final agent: one scale for all its runs
        steps = np.arange(1, deployment.shape[1] + 1)
        for i in range(columns):
            ax = axes[2 * b + 1, i]
            if i >= n_runs:
                ax.axis("off")
                continue
            ax.imshow(
                deployment[i].T,
                aspect="auto",
                origin="lower",
                cmap="viridis",
                vmin=-DECADES,
                vmax=0,
                extent=(steps[0], steps[-1], xs[0], xs[-1]),
            )
            ax.plot(steps, run.observations[axis.key][:, i, 0], color="r", linewidth=1.2)
            for border in axis.region or ():
                ax.axhline(border, color="w", linestyle="--", linewidth=0.8)
            ax.set_title(f"{name}, final agent\ndeployed on task {np.round(run.tasks[i], 2).tolist()}", fontsize=8)
            ax.set_xlabel("step of the BAMDP episode")
            ax.set_ylabel(f"{axis.label} (red: deployed)")
    fig.suptitle(f"bonus landscape of {cell}", fontsize=10)
    figures = out / grid.FIGURES
    figures.mkdir(parents=True, exist_ok=True)
    path = figures / f"bonus_{cell}.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    from hyperstate.evaluation.imports import import_modules

    parser = argparse.ArgumentParser(prog="python -m hyperstate.evaluation.diagnostics", description=__doc__)
    parser.add_argument("out", type=Path, help="a results folder written by evaluation/run.py")
    parser.add_argument("--cells", nargs="+", default=None, metavar="CELL", help="cell ids (default: all)")
    parser.add_argument("--import", dest="imports", nargs="+", default=[], metavar="MODULE")
    args = parser.parse_args(argv)
    import_modules(args.imports)
    cells = args.cells or grid.cell_ids(args.out)
    for cell in cells:
        path = cell_diagnostics(args.out, cell)
        print(f"{cell}: {path if path is not None else 'no bonus landscape (no evaluable bonus or snapshots)'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
