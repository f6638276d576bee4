"""The cross-task report (hyperstate-report) on tiny hand-made grids: normalisation, rliable's IQM and
probability of improvement against independent computations, what is left out and why, the files."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from hyperstate.evaluation import cross_task

ROOT = Path(__file__).resolve().parents[1]

# Online returns per (task, agent): one value per seed.
RETURNS = {
    "task_a": {"varibad": [0.0, 2.0, 4.0], "task_aware": [100.0, 100.0, 100.0], "hyperx": [60.0, 90.0, 30.0],
               "oracle": [0.0, 1.0, 5.0], "oracle_rh": [80.0, 20.0, 70.0]},
    "task_b": {"varibad": [-10.0, -10.0, -10.0], "task_aware": [10.0, 10.0, 10.0], "hyperx": [0.0, 10.0, 5.0],
               "oracle": [-10.0, -9.0, -10.0], "oracle_rh": [10.0, 8.0, -10.0]},
}  # fmt: skip


def write_grid(folder: Path, returns: dict, config: dict | None = None) -> Path:
    for task, agents in returns.items():
        for agent, values in agents.items():
            for seed, value in enumerate(values):
                cell = folder / "cells" / f"{agent}__{task}__s{seed}"
                cell.mkdir(parents=True)
                record = {"agent": agent, "task": task, "seed": seed, "complete": True,
                          "config": config or {"agent": agent}, "final": {"online_return": value}}  # fmt: skip
                (cell / "record.json").write_text(json.dumps(record))
    return folder


def normalised(task: str, agent: str) -> np.ndarray:
    low, high = np.mean(RETURNS[task]["varibad"]), np.mean(RETURNS[task]["task_aware"])
    return (np.array(RETURNS[task][agent]) - low) / (high - low)


def rows_of(path: Path) -> dict:
    with path.open() as f:
        return {(r["statistic"], r["agent"], r["task"]): r for r in csv.DictReader(f)}


def test_iqm_and_probability_of_improvement_are_rliables_on_the_normalised_scores(tmp_path):
    grids = [
        write_grid(tmp_path / "a", {"task_a": RETURNS["task_a"]}),
        write_grid(tmp_path / "b", {"task_b": RETURNS["task_b"]}),
    ]
    messages = []
    np.random.seed(123)
    before = np.random.random()
    np.random.seed(123)
    cross_task.report(grids, tmp_path / "out", reps=300, say=messages.append)
    assert np.random.random() == before  # the caller's global NumPy generator is left as it was
    rows = rows_of(tmp_path / "out" / "cross_task.csv")
    assert not messages
    norm = rows[("normaliser", "varibad..task_aware", "task_a")]
    assert float(norm["low"]) == 2.0 and float(norm["high"]) == 100.0
    for agent in ("hyperx", "oracle", "oracle_rh", "varibad", "task_aware"):
        row = rows[("iqm", agent, "")]
        scores = np.concatenate([normalised("task_a", agent), normalised("task_b", agent)])
        assert float(row["value"]) == pytest.approx(stats.trim_mean(scores, 0.25))  # IQM: the middle half's mean
        assert float(row["ci_low"]) <= float(row["value"]) <= float(row["ci_high"]) and row["runs"] == "6"
    assert float(rows[("iqm", "task_aware", "")]["value"]) == pytest.approx(1.0)
    # P(X > Y): per task, the share of seed pairs where X beats Y (ties count half), averaged over tasks.
    for x, y in (("hyperx", "varibad"), ("oracle_rh", "oracle")):
        by_task = []
        for task in RETURNS:
            a, b = normalised(task, x), normalised(task, y)
            by_task.append(np.mean([(u > v) + 0.5 * (u == v) for u in a for v in b]))
        row = rows[("probability_of_improvement", f"{x}>{y}", "")]
        assert float(row["value"]) == pytest.approx(np.mean(by_task))
        assert 0.0 <= float(row["ci_low"]) <= float(row["value"]) <= float(row["ci_high"]) <= 1.0
    assert (tmp_path / "out" / "cross_task.png").read_bytes()[:4] == b"\x89PNG"
    # The same seed gives the same report; another seed other bootstrap intervals.
    first = (tmp_path / "out" / "cross_task.csv").read_text()
    cross_task.report(grids, tmp_path / "again", reps=300)
    assert (tmp_path / "again" / "cross_task.csv").read_text() == first
    cross_task.report(grids, tmp_path / "other", reps=300, seed=1)
    assert (tmp_path / "other" / "cross_task.csv").read_text() != first


def test_what_cannot_be_compared_is_left_out_with_a_reason(tmp_path):
    returns = {task: dict(agents) for task, agents in RETURNS.items()}
    del returns["task_b"]["oracle"]  # oracle only on task_a
    returns["task_c"] = {"varibad": [5.0], "task_aware": [1.0], "hyperx": [3.0]}  # reference below baseline
    grid = write_grid(tmp_path / "g", returns)
    rival = write_grid(tmp_path / "rival", {"task_a": {"hyperx": [1.0, 2.0, 3.0, 4.0]}}, config={"other": 1})
    messages = []
    rows = cross_task.report([grid, rival], tmp_path / "out", reps=100, say=messages.append)
    text = "\n".join(messages)
    assert "task_c left out: task_aware (1.0) does not beat varibad (5.0)" in text
    assert "oracle scored on 1 of 2 tasks: no cell on task_b" in text
    assert "rival: left out hyperx (another configuration than in an earlier grid)" in text
    iqm = {r["agent"]: r for r in rows if r["statistic"] == "iqm"}
    assert set(iqm) == {"hyperx", "oracle", "oracle_rh", "task_aware", "varibad"}
    assert [r["task"] for a, r in sorted(iqm.items())] == ["", "task_a", "", "", ""]  # only oracle's is a subset
    # oracle, on task_a only: its IQM is over its task_a seeds, and P(oracle_rh > oracle) compares the two
    # on task_a alone, while hyperx > varibad is over both tasks.
    assert iqm["oracle"]["value"] == pytest.approx(stats.trim_mean(normalised("task_a", "oracle"), 0.25))
    assert iqm["oracle"]["runs"] == 3 and iqm["hyperx"]["runs"] == 6
    pairs = {r["agent"]: r for r in rows if r["statistic"] == "probability_of_improvement"}
    assert set(pairs) == {"hyperx>varibad", "oracle_rh>oracle"}
    a, b = normalised("task_a", "oracle_rh"), normalised("task_a", "oracle")
    beats = np.mean([(u > v) + 0.5 * (u == v) for u in a for v in b])
    assert pairs["oracle_rh>oracle"]["value"] == pytest.approx(beats)
    assert pairs["oracle_rh>oracle"]["task"] == "task_a" and pairs["hyperx>varibad"]["task"] == ""


def test_the_command_names_bad_input_in_one_line(tmp_path):
    def run(*args):
        return subprocess.run([sys.executable, str(ROOT / "evaluation" / "cross_task.py"), *map(str, args)],
                              capture_output=True, text=True, timeout=300)  # fmt: skip

    (tmp_path / "empty").mkdir()
    proc = run(tmp_path / "empty", "--out", tmp_path / "o")
    assert proc.returncode == 2 and "none of the folders is a grid" in proc.stderr
    grid = write_grid(tmp_path / "g", {"task_a": {"hyperx": [1.0]}})
    proc = run(grid, "--out", tmp_path / "o")
    assert proc.returncode == 1 and "no task has both varibad and task_aware" in proc.stderr
    proc = run(grid, "--pairs", "hyperx", "--out", tmp_path / "o")
    assert proc.returncode == 2 and "a pair is X:Y" in proc.stderr
    both = write_grid(tmp_path / "both", RETURNS)
    proc = run(both, "--reps", 50, "--out", tmp_path / "o")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().endswith(str(tmp_path / "o" / "cross_task.png"))


def test_the_results_table_gives_each_agents_mean_and_the_seeds_that_meet_the_tasks_criterion(tmp_path):
    """`--table`: tasks × agents, mean online return over seeds and, for a task with a success criterion
    (cheetah_dir_sparse: the turn pays), the seeds that meet it; an agent a task lacks is a dash."""
    grid = write_grid(tmp_path / "g", RETURNS)
    turn = tmp_path / "cheetah"
    finals = [  # pays; one way (correct 0.5); pays without wrong-first deployments
        {"online_return": 900.0, "correct_direction": 1.0, "return_wrong_first": 300.0},
        {"online_return": 430.0, "correct_direction": 0.5, "return_wrong_first": -20.0},
        {"online_return": 800.0, "correct_direction": 0.95},
    ]
    for seed, final in enumerate(finals):
        cell = turn / "cells" / f"oracle_rh__cheetah_dir_sparse__s{seed}"
        cell.mkdir(parents=True)
        record = {"agent": "oracle_rh", "task": "cheetah_dir_sparse", "seed": seed, "complete": True,
                  "config": {"agent": "oracle_rh"}, "final": final}  # fmt: skip
        (cell / "record.json").write_text(json.dumps(record))
    out = tmp_path / "table.md"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "evaluation" / "cross_task.py"), grid, turn, "--reps", "50", "--out",
         tmp_path / "o", "--table", out, "--table-link", "results/{task}.md"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    lines = out.read_text().splitlines()
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    assert header == ["task", "`oracle`", "`oracle_rh`", "`varibad`", "`hyperx`", "`task_aware`"]
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.strip("|").split("|")[1:]] for line in lines[2:]}
    assert rows["[`cheetah_dir_sparse`](results/cheetah_dir_sparse.md)"] == ["—", "710 (solved 2/3)", "—", "—", "—"]
    expected = [f"{np.mean(RETURNS['task_a'][a]):,.0f}" for a in ("oracle", "oracle_rh", "varibad", "hyperx")]
    assert rows["[`task_a`](results/task_a.md)"] == [*expected, "100"]


def test_the_task_table_gives_seeds_mean_solved_share_and_metric_means(tmp_path):
    """A results page's table: per agent each seed's return (— for a missing seed), the mean, the seeds
    that meet the task's criterion, with `share` their Wilson 95 % interval (scipy's, as in summary.csv),
    and the seeds' mean of each named metric; `task_aware` last whatever its mean."""
    finals = {
        "oracle_rh": [{"online_return": 900.0, "correct_direction": 1.0, "return_wrong_first": 300.0, "stuck": 0.0},
                      {"online_return": 430.0, "correct_direction": 0.5, "return_wrong_first": -20.0, "stuck": 0.5},
                      {"online_return": 800.0, "correct_direction": 0.95, "stuck": 0.1}],
        "oracle": [{"online_return": -2.0, "correct_direction": 0.0, "stuck": 0.0},
                   {"online_return": -4.0, "correct_direction": 0.0}],
        "task_aware": [{"online_return": 1.0, "correct_direction": 1.0, "stuck": 0.0}],
    }  # fmt: skip
    for agent, per_seed in finals.items():
        for seed, final in enumerate(per_seed):
            cell = tmp_path / "cells" / f"{agent}__cheetah_dir_sparse__s{seed}"
            cell.mkdir(parents=True)
            record = {"agent": agent, "task": "cheetah_dir_sparse", "seed": seed, "complete": True,
                      "config": {"agent": agent}, "final": final}  # fmt: skip
            (cell / "record.json").write_text(json.dumps(record))
    lines = cross_task.task_table(tmp_path, ["stuck"], decimals=0, share=True, say=lambda _: None).splitlines()
    assert lines[0] == "| agent | online return, seeds 0 / 1 / 2 | mean | solved | share (Wilson 95 %) | `stuck` |"
    wilson = stats.binomtest(2, 3).proportion_ci(confidence_level=0.95, method="wilson")
    share = f"0.67 ({wilson.low:.2f}–{wilson.high:.2f})"
    assert lines[2] == f"| `oracle_rh` | 900 / 430 / 800 | 710 | 2 of 3 | {share} | 0.20 |"
    assert lines[3] == "| `oracle` | -2 / -4 / — | -3 | 0 of 2 | 0.00 (0.00–0.66) | 0.00 |"
    assert lines[4].startswith("| `task_aware` | 1 / — / — | 1 | 1 of 1 |")
    without = cross_task.task_table(tmp_path, [], say=lambda _: None).splitlines()
    assert without[0] == "| agent | online return, seeds 0 / 1 / 2 | mean | solved |"
    assert without[2] == "| `oracle_rh` | 900.0 / 430.0 / 800.0 | 710.0 | 2 of 3 |"
