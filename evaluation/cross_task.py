"""The cross-task report: committed grids of several tasks in one score, with rliable.

    hyperstate-report docs/results/* [--out runs/cross_task] [--low-agent varibad] [--high-agent task_aware]
                      [--agents A ...] [--pairs hyperx:varibad oracle_rh:oracle] [--reps 2000] [--seed 0]

Each task's online return at deployment (every cell's `record["final"]["online_return"]`) is normalised
between two agents of the same grid: 0 at the mean of `--low-agent` (default `varibad`, the meta-learner
without an exploration bonus: the score says what exploration added) and 1 at the mean of `--high-agent`
(default `task_aware`, the reference that is told the task: what knowing it would earn). A task whose grid
lacks either agent, or where the high one does not beat the low one, is left out, with a message.
Over tasks and seeds, with rliable (Agarwal et al., 2021) and stratified bootstrap (runs resampled within
each task), the report gives:
- the IQM of the normalised score per agent, with 95 % CIs;
- performance profiles: the fraction of runs whose normalised score exceeds τ, with 95 % CIs;
- the probability of improvement of one agent over another (`--pairs X:Y`: P(X > Y)), with 95 % CIs.
An agent is scored on the tasks that have it (a belief oracle only where the task has an exact belief),
with a message where those are not all; per task on its first k seeds, k the fewest seeds it has on any
of them (a bootstrap over tasks needs as many runs per task). A probability of improvement compares two
agents on the tasks both have. A row over fewer than all the tasks names its tasks (`task`, joined by +).
Writes OUT/cross_task.csv (one row per statistic: `normaliser` per task with its `low` and `high`
returns, `iqm` per agent and `probability_of_improvement` per pair with `value`, `ci_low`, `ci_high` and
the `runs` behind them; the profiles are in the figure) and OUT/cross_task.png. `--table FILE` also
writes the README's table: tasks × agents, each agent's mean online return and, where the task declares a
success criterion, how many seeds meet it.
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from hyperstate.evaluation import cli
from hyperstate.evaluation.cell import load_records
from hyperstate.files import write_text_atomic

CSV_NAME, FIGURE_NAME = "cross_task.csv", "cross_task.png"
FIELDS = ("statistic", "agent", "task", "value", "ci_low", "ci_high", "runs", "low", "high")
DEFAULT_PAIRS = ("hyperx:varibad", "oracle_rh:oracle")
TAUS = np.linspace(-0.5, 1.5, 81)  # normalised scores drawn in the performance profile


class ReportError(ValueError):
    """Grids that cannot make a cross-task report; one line for the user."""


def finished_cells(grids: list[Path], say=print) -> dict[str, dict[str, dict[int, dict]]]:
    """{task: {agent: {seed: final deployment metrics}}} from the finished cells of `grids`. An agent is one
    configuration: its cells on a task come from the grids whose configuration for it equals the first one
    found (runtime settings aside); a cell (agent, task, seed) in several grids is taken from the first."""
    from hyperstate.evaluation.merge import comparable

    table: dict[str, dict[str, dict[int, dict]]] = defaultdict(lambda: defaultdict(dict))
    configs: dict[tuple[str, str], dict] = {}
    left_out = defaultdict(set)
    for folder in grids:
        records = [r for r in load_records(folder) if r.get("complete") and r.get("final")]
        if not records:
            raise ReportError(f"{folder} holds no finished cell (cells/*/record.json with a final deployment)")
        for r in sorted(records, key=lambda r: (r["task"], r["agent"], r["seed"])):
            key, config = (r["task"], r["agent"]), comparable(r.get("config", {}))
            if configs.setdefault(key, config) != config:
                left_out[folder].add(f"{r['agent']} (another configuration than in an earlier grid)")
                continue
            seeds = table[r["task"]][r["agent"]]
            if r["seed"] in seeds:
                left_out[folder].add(f"{r['agent']} s{r['seed']} (already taken from an earlier grid)")
                continue
            seeds[r["seed"]] = r["final"]
    for folder, cells in left_out.items():
        say(f"cross-task report: {folder}: left out {', '.join(sorted(cells))}")
    return table


def returns_by_task(grids: list[Path], say=print) -> dict[str, dict[str, dict[int, float]]]:
    """{task: {agent: {seed: online return at deployment}}}, the cells chosen as `finished_cells` does."""
    return {
        task: {agent: {s: float(f["online_return"]) for s, f in seeds.items()} for agent, seeds in agents.items()}
        for task, agents in finished_cells(grids, say).items()
    }


def _success_criterion(task: str):
    """The task's success criterion (`suite.success`), None where it has none or is not registered in this
    process (its table then gives returns only)."""
    from hyperstate import suite

    try:
        return suite.success(task)
    except ValueError:
        return None


def results_table(grids: list[Path], agents: list[str] | None = None, link: str | None = None, say=print) -> str:
    """A Markdown table, tasks × agents: each agent's mean online return at deployment over its seeds and,
    for tasks that declare a success criterion (`suite.register(..., success=)`), the seeds that meet it
    (`solved k/n`). `link` (e.g. "docs/results/{task}.md") makes each task name a link."""
    from hyperstate.agents import GRID_PRESETS
    from hyperstate.evaluation.report import success_share  # imports the suite: only where a table is made

    cells = finished_cells(grids, say)
    present = {a for per_task in cells.values() for a in per_task}
    # The meta-learners first, the task-aware reference (not a meta-learner) last.
    learners = [a for a in GRID_PRESETS if a != "task_aware"]
    default = [*learners, *sorted(present - set(learners) - {"task_aware"}), "task_aware"]
    order = [a for a in (agents or default) if a in present]
    lines = [
        "| task | " + " | ".join(f"`{a}`" for a in order) + " |",
        "|---|" + "---|" * len(order),
    ]
    for task in sorted(cells):
        success = _success_criterion(task)
        entries = []
        for agent in order:
            finals = list(cells[task].get(agent, {}).values())
            if not finals:
                entries.append("—")
                continue
            mean = float(np.mean([f["online_return"] for f in finals]))
            solved = f" (solved {success_share(finals, success)['success_seeds']}/{len(finals)})" if success else ""
            entries.append(f"{round(mean) or 0:,}{solved}")  # `or 0`: no "-0" for a mean in (-0.5, 0)
        name = f"[`{task}`]({link.format(task=task)})" if link else f"`{task}`"
        lines.append(f"| {name} | " + " | ".join(entries) + " |")
    return "\n".join(lines) + "\n"


def task_table(grid: Path, metrics: list[str], decimals: int = 1, share: bool = False, say=print) -> str:
    """A Markdown table of one task's grid, an agent per row (the highest mean first, `task_aware` last):
    the online return of each seed (— for a seed it lacks), their mean, the seeds that meet the task's
    success criterion (`solved k of n`, where the task declares one; with `share`, also their share and its
    Wilson 95 % interval, as in `summary.csv`) and the mean over seeds of each named final-deployment
    metric. The results pages' tables are these (tests/test_docs.py)."""
    from hyperstate.evaluation.report import success_share

    cells = finished_cells([grid], say)
    if len(cells) != 1:
        raise ReportError(f"{grid}: a task table is of one task's grid, found tasks {sorted(cells)}")
    ((task, agents),) = cells.items()
    success = _success_criterion(task)
    seeds = sorted({s for per_agent in agents.values() for s in per_agent})
    header = ["agent", f"online return, seeds {' / '.join(str(s) for s in seeds)}", "mean"]
    header += ["solved"] if success else []
    header += ["share (Wilson 95 %)"] if success and share else []
    header += [f"`{m}`" for m in metrics]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]

    def mean_return(agent: str) -> float:
        return float(np.mean([f["online_return"] for f in agents[agent].values()]))

    order = sorted((a for a in agents if a != "task_aware"), key=lambda a: (-mean_return(a), a))
    for agent in [*order, *(["task_aware"] if "task_aware" in agents else [])]:
        finals = [agents[agent][s] for s in sorted(agents[agent])]
        by_seed = [agents[agent].get(s) for s in seeds]  # a seed the agent lacks (not finished): —
        row = [f"`{agent}`", " / ".join("—" if f is None else f"{f['online_return']:,.{decimals}f}" for f in by_seed),
               f"{mean_return(agent):,.{decimals}f}"]  # fmt: skip
        if success:
            solved = success_share(finals, success)
            row.append(f"{solved['success_seeds']} of {len(finals)}")
            if share:
                low, high = solved["success_ci95_low"], solved["success_ci95_high"]
                row.append(f"{solved['success_share']:.2f} ({low:.2f}–{high:.2f})")
        for m in metrics:
            values = [f[m] for f in finals if f.get(m) is not None]
            row.append(f"{np.mean(values):.2f}" if values else "—")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def normalisers(table, low_agent: str, high_agent: str, say=print) -> dict[str, tuple[float, float]]:
    """Per task, (low, high): the mean returns of the two normalising agents; tasks without them skipped."""
    out = {}
    for task, agents in sorted(table.items()):
        missing = [a for a in (low_agent, high_agent) if a not in agents]
        if missing:
            say(f"cross-task report: {task} left out: its grid has no {' and no '.join(missing)} cell")
            continue
        low, high = (float(np.mean(list(agents[a].values()))) for a in (low_agent, high_agent))
        if not high > low:
            say(f"cross-task report: {task} left out: {high_agent} ({high:.1f}) does not beat {low_agent} ({low:.1f})")
            continue
        out[task] = (low, high)
    return out


def score_matrices(
    table, scales, agents: list[str] | None, say=print
) -> tuple[dict[str, np.ndarray], dict[str, list[str]]]:
    """{agent: (runs, tasks) normalised scores} over the normalised tasks that have the agent, in the order
    of `scales`, and {agent: those tasks} (the matrix's columns). An agent missing from some tasks (a belief
    oracle on a task without an exact belief) is scored on the others, with a message."""
    tasks = list(scales)
    candidates = agents or sorted({a for t in tasks for a in table[t]})
    matrices, tasks_of = {}, {}
    for agent in candidates:
        present = [t for t in tasks if agent in table[t]]
        if not present:
            say(f"cross-task report: {agent} left out: no cell on {', '.join(tasks)}")
            continue
        if len(present) < len(tasks):
            lacking = [t for t in tasks if t not in present]
            scored = f"{len(present)} of {len(tasks)} tasks"
            say(f"cross-task report: {agent} scored on {scored}: no cell on {', '.join(lacking)}")
        runs = min(len(table[t][agent]) for t in present)
        columns = []
        for t in present:
            low, high = scales[t]
            seeds = sorted(table[t][agent])[:runs]
            columns.append([(table[t][agent][s] - low) / (high - low) for s in seeds])
        matrices[agent], tasks_of[agent] = np.array(columns).T, present
    if not matrices:
        raise ReportError("no agent has a cell on a normalised task")
    return matrices, tasks_of


def paired(matrices, tasks_of, x: str, y: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """X's and Y's scores on the tasks both have, on as many seeds each (a paired bootstrap needs both)."""
    common = [t for t in tasks_of[x] if t in tasks_of[y]]
    a = matrices[x][:, [tasks_of[x].index(t) for t in common]]
    b = matrices[y][:, [tasks_of[y].index(t) for t in common]]
    runs = min(len(a), len(b))
    return a[:runs], b[:runs], common


def interval_estimates(
    matrices, tasks_of: dict[str, list[str]], pairs: list[tuple[str, str]], reps: int, seed: int
) -> tuple[list[dict], dict]:
    """The CSV's `iqm` and `probability_of_improvement` rows, and the performance profiles. `tasks_of` names
    each agent's columns (`score_matrices`); a row's `task` lists the tasks behind it where they are not all
    of them."""
    import warnings

    # rliable's bootstraps (arch's) draw from NumPy's global generator; a RandomState handed to them is not
    # used alike by every call. So each call starts from `seed` there, and the caller's state is restored.
    saved = np.random.get_state()
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="random_state is deprecated", category=FutureWarning)
            return _interval_estimates(matrices, tasks_of, pairs, reps, seed)
    finally:
        np.random.set_state(saved)


def _interval_estimates(matrices, tasks_of, pairs, reps, seed):
    from rliable import library as rly
    from rliable import metrics

    every = {t for tasks in tasks_of.values() for t in tasks}

    def subset(tasks: list[str]) -> str:
        return "" if set(tasks) == every else "+".join(tasks)

    def iqm(scores):
        return np.array([metrics.aggregate_iqm(scores)])

    np.random.seed(seed)
    point, ci = rly.get_interval_estimates(matrices, iqm, reps=reps)
    rows = [
        {"statistic": "iqm", "agent": a, "task": subset(tasks_of[a]), "value": point[a][0], "ci_low": ci[a][0, 0],
         "ci_high": ci[a][1, 0], "runs": matrices[a].size}
        for a in matrices
    ]  # fmt: skip
    present = {f"{x}>{y}": paired(matrices, tasks_of, x, y) for x, y in pairs if x in matrices and y in matrices}
    present = {k: v for k, v in present.items() if v[2]}  # two agents without a common task: no comparison
    if present:
        pair_scores = {k: (a, b) for k, (a, b, _) in present.items()}
        np.random.seed(seed)
        point, ci = rly.get_interval_estimates(pair_scores, metrics.probability_of_improvement, reps=reps)
        rows += [
            {"statistic": "probability_of_improvement", "agent": k, "task": subset(present[k][2]),
             "value": float(np.squeeze(point[k])),
             "ci_low": float(np.squeeze(ci[k][0])), "ci_high": float(np.squeeze(ci[k][1])),
             "runs": pair_scores[k][0].size + pair_scores[k][1].size}
            for k in pair_scores
        ]  # fmt: skip
    np.random.seed(seed)
    profiles, profile_cis = rly.create_performance_profile(matrices, TAUS, reps=reps)
    return rows, {"profiles": profiles, "cis": profile_cis}


def write_figure(path: Path, rows: list[dict], profiles: dict, title: str = "") -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    iqm = [r for r in rows if r["statistic"] == "iqm"]
    improvement = [r for r in rows if r["statistic"] == "probability_of_improvement"]
    fig, (iqm_ax, profile_ax, poi_ax) = plt.subplots(1, 3, figsize=(16.5, 4.2))
    colors = dict(zip(profiles["profiles"], plt.rcParams["axes.prop_cycle"].by_key()["color"] * 4, strict=False))
    for k, r in enumerate(iqm):
        iqm_ax.errorbar(r["value"], k, xerr=[[r["value"] - r["ci_low"]], [r["ci_high"] - r["value"]]],
                        fmt="o", color=colors[r["agent"]], capsize=4)  # fmt: skip
    # An agent scored on fewer tasks than the others says on how many.
    iqm_ax.set_yticks(range(len(iqm)), [_label(r) for r in iqm])
    iqm_ax.axvline(0, color="0.6", linewidth=1)
    iqm_ax.axvline(1, color="0.6", linewidth=1, linestyle="--")
    iqm_ax.set_xlabel("IQM of the normalised score (95 % CI)")
    for agent, profile in profiles["profiles"].items():
        low, high = profiles["cis"][agent]
        profile_ax.plot(TAUS, profile, color=colors[agent], label=agent)
        profile_ax.fill_between(TAUS, low, high, color=colors[agent], alpha=0.15)
    profile_ax.set_xlabel("normalised score τ")
    profile_ax.set_ylabel("fraction of runs with score > τ")
    profile_ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)  # off the curves
    for k, r in enumerate(improvement):
        poi_ax.errorbar(r["value"], k, xerr=[[r["value"] - r["ci_low"]], [r["ci_high"] - r["value"]]],
                        fmt="o", color="k", capsize=4)  # fmt: skip
    poi_ax.set_yticks(range(len(improvement)), [_label(r).replace(">", " > ") for r in improvement])
    poi_ax.axvline(0.5, color="0.6", linewidth=1, linestyle="--")
    poi_ax.set_xlim(0, 1)
    poi_ax.set_ylim(-0.5, len(improvement) - 0.5)
    poi_ax.set_xlabel("probability of improvement (95 % CI)")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _label(row: dict) -> str:
    tasks = row.get("task") or ""
    count = tasks.count("+") + 1
    return f"{row['agent']} ({count} task{'s' if count > 1 else ''})" if tasks else row["agent"]


def report(
    grids: list[Path],
    out: Path,
    *,
    low_agent: str = "varibad",
    high_agent: str = "task_aware",
    agents: list[str] | None = None,
    pairs: list[tuple[str, str]] | None = None,
    reps: int = 2000,
    seed: int = 0,
    say=print,
) -> list[dict]:
    """Writes OUT/cross_task.csv and OUT/cross_task.png from `grids`; returns the CSV's rows."""
    table = returns_by_task(grids, say)
    scales = normalisers(table, low_agent, high_agent, say)
    if not scales:
        raise ReportError(
            f"no task has both {low_agent} and {high_agent} with {high_agent} ahead: nothing to normalise"
        )
    matrices, tasks_of = score_matrices(table, scales, agents, say)
    pairs = [tuple(p.split(":")) for p in DEFAULT_PAIRS] if pairs is None else pairs
    rows = [
        {"statistic": "normaliser", "agent": f"{low_agent}..{high_agent}", "task": t, "low": low, "high": high}
        for t, (low, high) in scales.items()
    ]  # fmt: skip
    estimated, profiles = interval_estimates(matrices, tasks_of, pairs, reps, seed)
    rows += estimated
    out.mkdir(parents=True, exist_ok=True)
    with (out / CSV_NAME).open("w", newline="") as f:
        writer = csv.DictWriter(f, FIELDS)
        writer.writeheader()
        writer.writerows({k: r.get(k, "") for k in FIELDS} for r in rows)
    title = f"{len(scales)} task(s): {', '.join(scales)}; normalised score 0 = {low_agent}, 1 = {high_agent}"
    write_figure(out / FIGURE_NAME, rows, profiles, title)
    return rows


def _pair(text: str) -> tuple[str, str]:
    x, sep, y = text.partition(":")
    if not sep or not x or not y:
        raise argparse.ArgumentTypeError(f"a pair is X:Y (P(X > Y)), got {text!r}")
    return x, y


def main(argv: list[str] | None = None) -> int:
    prog = cli.program_name("evaluation/cross_task.py")
    parser = cli.OneLineParser(prog=prog, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("grids", nargs="+", type=Path, help="grid folders (evaluation/run.py or merge.py --out)")
    parser.add_argument("--out", type=Path, default=Path("runs/cross_task"))
    parser.add_argument("--low-agent", default="varibad", help="the agent each task's score 0 is (mean)")
    parser.add_argument("--high-agent", default="task_aware", help="the agent each task's score 1 is (mean)")
    parser.add_argument("--agents", nargs="+", default=None, help="agents to report (default: all)")
    pairs_help = f"X:Y, P(X > Y) (default: {' '.join(DEFAULT_PAIRS)})"
    parser.add_argument("--pairs", nargs="+", type=_pair, default=None, help=pairs_help)
    parser.add_argument("--reps", type=int, default=2000, help="bootstrap replications")
    parser.add_argument("--seed", type=int, default=0, help="the bootstrap's seed")
    parser.add_argument("--table", type=Path, default=None, help="also write the tasks × agents Markdown table here")
    parser.add_argument("--table-link", default=None, help="each task's link in the table, e.g. docs/{task}.md")
    args = parser.parse_args(argv)
    grids = [g for g in args.grids if (g / "cells").is_dir()]
    others = [str(g) for g in args.grids if g.is_dir() and g not in grids]  # plain files are passed over
    if others:
        print(f"{prog}: not grids (no cells/), left out: {', '.join(others)}", file=sys.stderr)
    if not grids:
        parser.error("none of the folders is a grid (a folder with cells/)")
    try:
        rows = report(grids, args.out, low_agent=args.low_agent, high_agent=args.high_agent, agents=args.agents,
                      pairs=args.pairs, reps=args.reps, seed=args.seed,
                      say=lambda m: print(f"{prog}: {m.split(': ', 1)[1]}", file=sys.stderr))  # fmt: skip
    except ReportError as e:
        parser.exit(1, f"{prog}: {e}\n")
    if args.table is not None:
        args.table.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(args.table, results_table(grids, args.agents, args.table_link, say=lambda m: None))
        print(args.table)
    for r in rows:
        if r["statistic"] != "normaliser":
            print(f"{r['statistic']:28s} {r['agent']:24s} {r['value']:7.3f}  [{r['ci_low']:.3f}, {r['ci_high']:.3f}]")
    print(f"{args.out / CSV_NAME}\n{args.out / FIGURE_NAME}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
