"""Reports from `results.json`: `summary.csv`, figures, and the text table printed at the end."""

from __future__ import annotations

import csv
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

from hyperstate import suite
from hyperstate.evaluation import grid
from hyperstate.evaluation.stats import bootstrap_ci, iqm, mean_ci_curve
from hyperstate.files import replacing

REFERENCE_AGENT = "task_aware"
SUMMARY_FIELDS = [
    "agent",
    "task",
    "seeds",
    "online_return_mean",
    "online_return_iqm",
    "ci95_low",
    "ci95_high",
    "success_seeds",
    "success_share",
    "success_ci95_low",
    "success_ci95_high",
    "reference_return",
    "regret",
    "bayes_estimate",
    "gap_to_bayes",
    "adaptive_reference_return",
    "probe_kl_after",
    "probe_accuracy_after",
    "final_coverage",
]
METRICS = ("probe_kl_after", "probe_accuracy_after")


def _by_agent_task(records: list[dict]) -> dict[tuple[str, str], list[dict]]:
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in records:
        if r.get("final") is not None:
            groups[(r["agent"], r["task"])].append(r)
    return groups


def summary_rows(records: list[dict]) -> list[dict]:
    """One row per (agent, task): mean, IQM and 95 % bootstrap CI (of the mean) over seeds."""
    groups = _by_agent_task(records)
    rows = []
    for (agent, task), cell in sorted(groups.items()):
        returns = np.array([r["final"]["online_return"] for r in cell])
        low, high = bootstrap_ci(returns)
        reference = groups.get((REFERENCE_AGENT, task))
        ref = float(np.mean([r["final"]["online_return"] for r in reference])) if reference else None
        estimator = suite.bayes_estimate(task)
        bayes = None
        if reference and estimator is not None:
            per_task = np.concatenate([r["final"]["online_return_per_task"] for r in reference])
            bayes = estimator(per_task)
        adaptive = [
            r["final"]["certainty_equivalent"]["online_return"]
            for r in reference or []
            if r["final"].get("certainty_equivalent")
        ]
        coverage = [r["curve"][-1].get("coverage") for r in cell if r["curve"]]
        coverage = [c for c in coverage if c is not None]
        row = {
            "agent": agent,
            "task": task,
            "seeds": len(cell),
            "online_return_mean": float(returns.mean()),
            "online_return_iqm": iqm(returns),
            "ci95_low": low,
            "ci95_high": high,
            "reference_return": ref,
            "regret": None if ref is None else ref - float(returns.mean()),
            "bayes_estimate": bayes,
            "gap_to_bayes": None if bayes is None else bayes - float(returns.mean()),
            "adaptive_reference_return": float(np.mean(adaptive)) if adaptive else None,
            "final_coverage": float(np.mean(coverage)) if coverage else None,
        }
        row.update(success_share([r["final"] for r in cell], suite.success(task)))
        for metric in METRICS + _task_metric_names(cell):
            values = [r["final"].get(metric) for r in cell if r["final"].get(metric) is not None]
            row[metric] = float(np.mean(values)) if values else None
        rows.append(row)
    return rows


def success_share(finals: list[dict], success) -> dict:
    """Of the seeds' final deployments, how many solved the task (its `suite.register(..., success=)`
    criterion), their share and its Wilson 95 % interval; empty for tasks without a criterion."""
    if success is None:
        return {}
    from scipy.stats import binomtest

    solved = sum(bool(success(f)) for f in finals)
    interval = binomtest(solved, len(finals)).proportion_ci(confidence_level=0.95, method="wilson")
    return {
        "success_seeds": solved,
        "success_share": solved / len(finals),
        "success_ci95_low": float(interval.low),
        "success_ci95_high": float(interval.high),
    }


def _task_metric_names(cell: list[dict]) -> tuple[str, ...]:
    """The deployed-exploration metrics the cell's task declares (`suite.register(..., metrics=...)`)."""
    names = {n for r in cell for n in r["final"].get("exploration_metric_names", ())}
    return tuple(sorted(names - set(METRICS)))


def write_summary(out: Path, records: list[dict]) -> list[dict]:
    rows = summary_rows(records)
    extra = sorted({k for row in rows for k in row} - set(SUMMARY_FIELDS))
    fields = SUMMARY_FIELDS + extra  # the tasks' declared metrics go last
    with replacing(out / grid.SUMMARY) as tmp, tmp.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if row.get(k) is None else row[k] for k in fields})
    return rows


def text_table(rows: list[dict]) -> str:
    """The one-screen summary printed at the end of a run."""

    def fmt(v, spec=".1f"):
        return "-" if v is None else format(v, spec)

    wa = max([20, *(len(r["agent"]) for r in rows)])
    wt = max([20, *(len(r["task"]) for r in rows)])
    header = (
        f"{'agent':<{wa}} {'task':<{wt}} {'seeds':>5} {'mean':>9} {'IQM':>9} {'95% CI':>19} {'regret':>9} "
        f"{'to Bayes':>9}"
    )
    lines = [header, "-" * len(header)]
    for r in rows:
        ci = f"[{fmt(r['ci95_low'])}, {fmt(r['ci95_high'])}]"
        lines.append(
            f"{r['agent']:<{wa}} {r['task']:<{wt}} {r['seeds']:>5} {fmt(r['online_return_mean']):>9} "
            f"{fmt(r['online_return_iqm']):>9} {ci:>19} {fmt(r['regret']):>9} {fmt(r['gap_to_bayes']):>9}"
        )
    return "\n".join(lines)


def bayes_bracket(row: dict) -> list[tuple[float, str, str]]:
    """The Bayes-optimal bracket to draw for a summary row: (value, label, line style) pairs.

    The Bayes-adaptive reference (certainty equivalence) is a policy that runs without knowing the task,
    so its measured return is a lower bound on the Bayes-optimal return whatever its quality. The upper
    estimate is derived from the task-aware reference's returns; it is a bound only if that reference
    is good, and a value below the measured lower bound proves it is not: then it is left out, and the
    label says so.
    """
    lower, upper = row.get("adaptive_reference_return"), row.get("bayes_estimate")
    lines = []
    if upper is not None and (lower is None or upper >= lower):
        lines.append((upper, "Bayes-optimal, upper estimate", "--"))
    if lower is not None:
        label = "Bayes-adaptive reference (lower bound)"
        if upper is not None and upper < lower:
            label += f"; upper estimate {upper:.0f} not drawn: below it (reference undertrained)"
        lines.append((lower, label, ":"))
    return lines


def write_figures(out: Path, records: list[dict]) -> list[Path]:
    """Per task: learning curves (mean over seeds, 95 % CI band), beside hyper-state coverage where the
    task measures it; and behaviour plots per agent × task (`drawn_cells`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figures = out / grid.FIGURES
    figures.mkdir(parents=True, exist_ok=True)
    written = []
    tasks = sorted({r["task"] for r in records})
    bracket = {row["task"]: row for row in summary_rows(records)}  # Bayes-optimal bracket per task
    for task in tasks:
        path = _curves_plot(records, task, bracket.get(task, {}), figures, plt)
        if path is not None:
            written.append(path)
    for task in tasks:
        path = _probe_plot(records, task, figures, plt)
        if path is not None:
            written.append(path)
    for cells in _by_agent_task(records).values():
        for record in drawn_cells(cells):
            path = _behaviour_plot(out, record, figures, plt)
            if path is not None:
                written.append(path)
    return written


def drawn_cells(cells: list[dict]) -> list[dict]:
    """The cells of one agent × task whose behaviour is drawn, lowest seed first: the lowest seed, the same
    figure whatever seeds a grid adds, and the seeds with the lowest and the highest online return where
    those are others, so that a failing seed and the agent at its best both have their picture."""
    first = min(cells, key=lambda r: r["seed"])
    worst = min(cells, key=lambda r: (r["final"].get("online_return", np.inf), r["seed"]))
    best = min(cells, key=lambda r: (-r["final"].get("online_return", -np.inf), r["seed"]))
    drawn = {id(r): r for r in (first, worst, best)}
    return sorted(drawn.values(), key=lambda r: r["seed"])


def _curves_plot(records: list[dict], task: str, bracket_row: dict, figures: Path, plt) -> Path | None:
    """Online return at deployment over training (mean over seeds, 95 % CI band) with the Bayes bracket,
    beside hyper-state coverage where the task measures it."""
    if not any(r["curve"] for r in records if r["task"] == task):
        return None  # deployed saved agents (run.py --deploy): no training, no curves
    by_agent = {}
    for agent in sorted({r["agent"] for r in records if r["task"] == task}):
        cells = [r for r in records if r["task"] == task and r["agent"] == agent and r["curve"]]
        if cells:
            length = min(len(r["curve"]) for r in cells)
            by_agent[agent] = (cells, length)
    # Coverage is measured only where the task defines a hyper-state grid; without it, one panel.
    covered = {
        agent
        for agent, (cells, length) in by_agent.items()
        if all("coverage" in p for r in cells for p in r["curve"][:length])
    }
    if covered:
        fig, (ax, cov_ax) = plt.subplots(1, 2, figsize=(13, 4))
    else:
        fig, ax = plt.subplots(figsize=(8, 4))
    for agent, (cells, length) in by_agent.items():
        frames = np.array([p["frames"] for p in cells[0]["curve"][:length]])
        curves = np.array([[p["online_return"] for p in r["curve"][:length]] for r in cells])
        mean, low, high = mean_ci_curve(curves)
        (line,) = ax.plot(frames, mean, label=f"{agent} ({len(cells)})")
        ax.fill_between(frames, low, high, color=line.get_color(), alpha=0.2)
        if agent in covered:
            coverage = np.array([[p["coverage"] for p in r["curve"][:length]] for r in cells])
            mean, low, high = mean_ci_curve(coverage)
            cov_ax.plot(frames, mean, color=line.get_color(), label=agent)
            cov_ax.fill_between(frames, low, high, color=line.get_color(), alpha=0.2)
    for value, label, style in bayes_bracket(bracket_row):
        ax.axhline(value, color="0.3", linestyle=style, linewidth=1, label=label)
    ax.set_xlabel("frames")
    ax.set_ylabel("online return at deployment")
    ax.set_title(task)
    # Beside the axes, not on them: with a grid's nine agents a legend inside covers the curves.
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    if covered:
        cov_ax.set_xlabel("frames")
        cov_ax.set_ylabel("hyper-state coverage (position × belief cells visited)")
        cov_ax.set_title("pseudo-exploration during meta-training")
    fig.tight_layout()
    path = figures / f"curves_{task}.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _probe_plot(records: list[dict], task: str, figures: Path, plt) -> Path | None:
    """Belief probe per step of the BAMDP episode: KL(exact ‖ probe) and accuracy, mean over seeds."""
    by_agent = defaultdict(list)
    for r in records:
        if r["task"] == task and r.get("final") and r["final"].get("probe_kl_per_step"):
            by_agent[r["agent"]].append(r["final"])
    if not by_agent:
        return None
    fig, (kl_ax, acc_ax) = plt.subplots(1, 2, figsize=(11, 3.8))
    for agent, finals in sorted(by_agent.items()):
        kl = np.mean([f["probe_kl_per_step"] for f in finals], axis=0)
        acc = np.array([[np.nan if a is None else a for a in f["probe_accuracy_per_step"]] for f in finals])
        steps = np.arange(1, len(kl) + 1)
        (line,) = kl_ax.plot(steps, kl, label=f"{agent} ({len(finals)})")
        with warnings.catch_warnings():  # steps where no deployment is informed yet: NaN, not drawn
            warnings.simplefilter("ignore", RuntimeWarning)
            acc_ax.plot(steps, np.nanmean(acc, axis=0), color=line.get_color(), label=agent)
    kl_ax.set_xlabel("step of the BAMDP episode")
    kl_ax.set_ylabel("KL(exact belief ‖ probe) (nats)")
    kl_ax.set_title(f"belief probe on held-out deployments, {task}")
    kl_ax.legend(fontsize=8)
    acc_ax.set_xlabel("step of the BAMDP episode")
    acc_ax.set_ylabel("probe accuracy (informed deployments)")
    acc_ax.set_ylim(-0.05, 1.05)
    fig.tight_layout()
    path = figures / f"probe_{task}.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _behaviour_plot(out: Path, record: dict, figures: Path, plt) -> Path | None:
    """Position vs step of the final deployment, one line per distinct task, along the position axis the
    task declares (`suite.PositionAxis`), its region's borders dashed; or, for a task that declares a
    `suite.TopDownView` instead, the deployment's paths on the plane. None for a task with neither."""
    axis = suite.position_axis(record["task"])
    cell = grid.record_cell_id(record)
    npz = grid.cell_dir(out, cell) / grid.DEPLOYMENT
    if not npz.exists():
        return None
    if axis is None:
        view = suite.top_down(record["task"])
        if view is None:
            return None
        return _top_down_plot(np.load(npz), record, view, figures / f"behaviour_{cell}.png", plt)
    data = np.load(npz)
    if f"obs_{axis.key}" not in data:
        return None
    path = figures / f"behaviour_{cell}.png"
    x, tasks = data[f"obs_{axis.key}"][..., 0], data["tasks"]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    for value in np.unique(tasks, axis=0):
        i = int(np.flatnonzero((tasks == value).all(axis=1))[0])
        ax.plot(np.arange(1, len(x) + 1), x[:, i], label=f"task {value.tolist()}")
    for border in axis.region or ():
        ax.axhline(border, color="k", linestyle="--", linewidth=1)
    ax.set_xlabel("step of the BAMDP episode")
    ax.set_ylabel(axis.label)
    ax.set_title(f"{record['agent']} on {record['task']}, seed {record['seed']}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


TOP_DOWN_PANELS = 4  # distinct tasks drawn side by side in a top-down behaviour plot


def _top_down_plot(data, record: dict, view: suite.TopDownView, path: Path, plt) -> Path | None:
    """The final deployment's path on the plane for up to `TOP_DOWN_PANELS` distinct tasks, one panel
    each, over the scene the task draws (`view.draw_scene`); the start is a circle, the end a cross."""
    if f"obs_{view.key}" not in data:
        return None
    xy, tasks, rewards = data[f"obs_{view.key}"][..., :2], data["tasks"], data["rewards"]
    firsts = [int(np.flatnonzero((tasks == value).all(axis=1))[0]) for value in np.unique(tasks, axis=0)]
    firsts = sorted(firsts)[:TOP_DOWN_PANELS]
    x_min, x_max, y_min, y_max = view.extent
    aspect = (x_max - x_min) / (y_max - y_min)
    if aspect > 2:  # a wide scene: panels one above the other, each 8 inches wide
        width, height, rows, cols = 8.0, 8.0 / aspect, len(firsts), 1
    else:
        width, height, rows, cols = 3.2 * min(aspect, 1.0), 3.2 / max(aspect, 1.0), 1, len(firsts)
    figsize = (width * cols + 0.4, (height + 0.35) * rows + 0.5)
    fig, axes = plt.subplots(rows, cols, figsize=figsize, squeeze=False)
    for ax, i in zip(axes.ravel(), firsts, strict=True):
        if view.draw_scene is not None:
            view.draw_scene(ax, tasks[i])
        # One colour per MDP episode (the robot is reset between them); the start a circle, the end a cross.
        # The observed episode index: a step ending an episode shows the next one's start.
        episode = data["obs_inner_episode"][:, i, 0] if "obs_inner_episode" in data else np.zeros(len(xy))
        for k, value in enumerate(np.unique(episode)):
            steps = np.flatnonzero(episode == value)
            color = f"C{k}"
            label = f"episode {k + 1}" if len(np.unique(episode)) > 1 and i == firsts[0] else None
            ax.plot(xy[steps, i, 0], xy[steps, i, 1], "-", color=color, linewidth=1.5, alpha=0.8, label=label)
            ax.plot(*xy[steps[0], i], "o", color=color)
            ax.plot(*xy[steps[-1], i], "x", color=color, markersize=8)
        if i == firsts[0] and len(np.unique(episode)) > 1:
            ax.legend(fontsize=6, loc="lower left")
        ax.set_xlim(x_min, x_max)
        ax.set_ylim(y_min, y_max)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"return {rewards[:, i].sum():.1f}", fontsize=9)
    fig.suptitle(f"{record['agent']} on {record['task']}, seed {record['seed']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
