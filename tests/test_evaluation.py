"""evaluation/run.py: the results contract, metrics, errors, crash + resume, Ray."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import tomllib

from hyperstate import agents, suite
from hyperstate.agents import serialization
from hyperstate.evaluation import provenance, report
from hyperstate.evaluation.deploy import deploy, deployment_metrics, evaluation_tasks
from hyperstate.evaluation.stats import bootstrap_ci, iqm
from hyperstate.suite.cheetah_dir import BACKWARD, FORWARD
from hyperstate.suite.scripted import gait

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, str(ROOT / "evaluation" / "run.py")]
TINY_CONFIG = """
[all]
"ppo.num_envs" = 4
"ppo.rollout_length" = 50
"vae.batch_trajectories" = 2
"vae.subsample_elbos" = 10
"vae.subsample_decodes" = 10
"""


def run(args, **kwargs) -> subprocess.CompletedProcess:
    env = {**os.environ, "MUJOCO_GL": "disable"}
    return subprocess.run(RUN + [str(a) for a in args], capture_output=True, text=True, env=env, timeout=600, **kwargs)


@pytest.fixture
def tiny_config(tmp_path) -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(TINY_CONFIG)
    return path


def strip_times(records):
    """Results without wall-clock fields (which legitimately differ between runs)."""
    out = []
    for r in records:
        r = json.loads(json.dumps(r))
        for point in r["curve"]:
            point.pop("wall_seconds")
        r.pop("versions")
        out.append(r)
    return out


# Statistics -----------------------------------------------------------------------------------------
def test_iqm_and_bootstrap_ci():
    assert iqm(np.array([0.0, 1.0, 2.0, 3.0, 100.0, -100.0, 1.5, 2.5])) == pytest.approx(np.mean([1.0, 1.5, 2.0, 2.5]))
    low, high = bootstrap_ci(np.array([1.0, 2.0, 3.0, 4.0, 5.0]))
    assert 1.0 <= low < 3.0 < high <= 5.0
    assert bootstrap_ci(np.array([7.0])) == (7.0, 7.0)


# Deployment -----------------------------------------------------------------------------------------
def test_behaviour_is_drawn_for_the_lowest_the_worst_and_the_best_seed():
    def cell(seed, online_return):
        return {"seed": seed, "final": {"online_return": online_return}}

    cells = [cell(2, 5.0), cell(0, 3.0), cell(1, -7.0), cell(3, 4.0)]
    assert [r["seed"] for r in report.drawn_cells(cells)] == [0, 1, 2]
    assert [r["seed"] for r in report.drawn_cells([cell(1, 4.0), cell(0, -1.0)])] == [0, 1]
    assert [r["seed"] for r in report.drawn_cells([cell(1, -4.0), cell(0, 1.0)])] == [0, 1]
    assert [r["seed"] for r in report.drawn_cells([cell(0, 2.0), cell(1, 2.0)])] == [0]  # ties: lowest seed
    assert [r["seed"] for r in report.drawn_cells([cell(3, 1.0), cell(1, 2.0), cell(2, 1.0)])] == [1, 2]


def test_evaluation_tasks_cover_a_finite_prior():
    tasks = evaluation_tasks("cheetah_dir_sparse", 5)
    assert tasks.shape == (5, 1) and set(tasks[:, 0]) == {-1.0, 1.0}
    assert evaluation_tasks("cheetah_dir_sparse", 1).shape == (2, 1)  # every support point at least once


def test_online_return_matches_independent_rollouts():
    agent = agents.make("oracle", **{"ppo.num_envs": 4, "ppo.rollout_length": 50})
    agent.train("cheetah_dir_sparse", frames=400, seed=0, progress=False)
    tasks = np.array([[1.0], [-1.0]])
    deployment = deploy(agent, "cheetah_dir_sparse", tasks, episodes_per_task=2, seed=5)
    metrics = deployment_metrics(deployment, "cheetah_dir_sparse")
    # The same deployments, one dm_control environment at a time.
    totals, per_episode = [], []
    for i, s in enumerate(suite.spawn_seeds(5, 2)):
        env = suite.load("cheetah_dir_sparse", seed=s, privileged=True, episodes_per_task=2, direction=tasks[i, 0])
        step, state, rewards = env.reset(), None, []
        while not step.last():
            obs = {k: v[None] for k, v in step.observation.items()}
            action, state = agent.act(obs, state, reward=None if state is None else np.array([step.reward]))
            step = env.step(action[0])
            rewards.append(step.reward)
        totals.append(sum(rewards))
        per_episode.append([sum(rewards[:200]), sum(rewards[200:])])
    assert metrics["online_return"] == pytest.approx(np.mean(totals), rel=1e-6)
    np.testing.assert_allclose(metrics["episode_returns"], np.mean(per_episode, axis=0), rtol=1e-6)
    assert metrics["left_zone"] == 0.0 and metrics["first_exit_step"] is None


# The CLI ---------------------------------------------------------------------------------------------
def test_grid_writes_the_results_contract(tmp_path, tiny_config):
    out = tmp_path / "grid"
    proc = run(
        "--agents oracle varibad --tasks cheetah_dir_sparse --seeds 0 1 --frames 400 --eval-every 200 "
        f"--eval-tasks 4 --workers 2 --config {tiny_config} --out {out} --no-progress".split()
    )
    assert proc.returncode == 0, proc.stderr
    records = json.loads((out / "results.json").read_text())
    cells = {(r["agent"], r["task"], r["seed"]) for r in records}
    assert cells == {(a, "cheetah_dir_sparse", s) for a in ("oracle", "varibad", "task_aware") for s in (0, 1)}
    for r in records:
        assert set(r) >= {"agent", "task", "seed", "frames", "config", "curve", "final", "versions"}
        assert [p["frames"] for p in r["curve"]] == [200, 400]
        assert set(r["curve"][0]) == {
            "frames",
            "online_return",
            "online_return_stochastic",
            "episode_returns",
            "wall_seconds",
            "coverage",
            "advantage_std",
        }
        assert set(r["curve"][0]["advantage_std"]) == {"combined"}  # one value head: no bonus, no intrinsic head
        assert r["config"]["ppo"]["num_envs"] == 4 and r["config"]["belief"] in ("oracle", "varibad", "task_aware")
        final = r["final"]
        assert final["online_return"] == pytest.approx(np.mean(final["online_return_per_task"]))
        assert final["online_return"] == pytest.approx(r["curve"][-1]["online_return"])
        assert {"left_zone", "first_exit_step", "correct_direction", "stuck", "distance_correct"} <= set(final)
        assert r["versions"]["mujoco"] == "3.17.0" and r["versions"]["cpu"]  # floats depend on the CPU
        assert r["versions"]["cpu_id"] == provenance.cpu_identification()
        assert {"probe_kl", "probe_kl_after", "informed_fraction"} <= set(final)
        assert all(0.0 < p["coverage"] <= 1.0 for p in r["curve"])
        # The task-aware reference learns the dense counterpart; every agent is deployed on the task.
        assert r["trained_on"] == ("cheetah_dir" if r["agent"] == "task_aware" else "cheetah_dir_sparse")
        if r["agent"] == "task_aware":  # also deployed Bayes-adaptively (certainty equivalence)
            ce = final["certainty_equivalent"]
            assert len(ce["online_return_per_task"]) == 4 and "left_zone" in ce
        else:
            assert "certainty_equivalent" not in final
    with (out / "summary.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert {(row["agent"], row["seeds"]) for row in rows} == {("oracle", "2"), ("varibad", "2"), ("task_aware", "2")}
    for row in rows:
        finals = [r["final"]["online_return"] for r in records if r["agent"] == row["agent"]]
        assert float(row["online_return_mean"]) == pytest.approx(np.mean(finals))
        assert float(row["ci95_low"]) <= float(row["online_return_mean"]) <= float(row["ci95_high"])
        reference = np.mean([r["final"]["online_return"] for r in records if r["agent"] == "task_aware"])
        assert float(row["regret"]) == pytest.approx(reference - np.mean(finals))
        assert float(row["bayes_estimate"]) <= reference + 1e-9
        adaptive = [r["final"]["certainty_equivalent"]["online_return"] for r in records if r["agent"] == "task_aware"]
        assert float(row["adaptive_reference_return"]) == pytest.approx(np.mean(adaptive))
    figures = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert "curves_cheetah_dir_sparse.png" in figures and "probe_cheetah_dir_sparse.png" in figures
    assert all(len(r["final"]["probe_kl_per_step"]) == 200 for r in records)  # one BAMDP episode of 200 steps
    assert "behaviour_oracle__cheetah_dir_sparse__s0.png" in figures
    for agent in {r["agent"] for r in records}:  # the lowest seed and, where others, the worst and the best
        cells = [r for r in records if r["agent"] == agent]
        worst = min(cells, key=lambda r: (r["final"]["online_return"], r["seed"]))["seed"]
        best = min(cells, key=lambda r: (-r["final"]["online_return"], r["seed"]))["seed"]
        drawn = {f for f in figures if f.startswith(f"behaviour_{agent}__")}
        assert drawn == {f"behaviour_{agent}__cheetah_dir_sparse__s{seed}.png" for seed in {0, worst, best}}, agent
    assert all((out / "figures" / f).read_bytes()[:4] == b"\x89PNG" for f in figures)
    assert any((out / "tb").rglob("events.out.tfevents.*"))
    # Each invocation is recorded: its command as typed, the commit, then its end and wall time.
    start, end = [json.loads(line) for line in (out / "commands.jsonl").read_text().splitlines()]
    assert start["command"].endswith(f"--config {tiny_config} --out {out} --no-progress")
    assert start["command"].split()[:3] == ["evaluation/run.py", "--agents", "oracle"]
    assert start["git_commit"] == records[0]["versions"]["git_commit"] and start["cpu"]
    assert end == {**start, "ended": end["ended"], "wall_seconds": end["wall_seconds"], "failed_cells": 0}
    assert end["ended"] >= start["started"] and end["wall_seconds"] > 0
    assert "oracle" in proc.stdout and "IQM" in proc.stdout  # the closing text table

    # Grids written by older code, without `certainty_equivalent`, the per-step probe, a task metric or the
    # stochastic deployment, get them on --resume from what the cells saved, equal to a fresh run's.
    path = out / "cells" / "task_aware__cheetah_dir_sparse__s0" / "record.json"
    varibad_path = out / "cells" / "varibad__cheetah_dir_sparse__s1" / "record.json"
    record, varibad = json.loads(path.read_text()), json.loads(varibad_path.read_text())
    expected = record["final"].pop("certainty_equivalent")
    expected_kl = varibad["final"].pop("probe_kl_per_step")
    del varibad["final"]["probe_accuracy_per_step"]
    expected_turned = varibad["final"].pop("turned_around")
    expected_stochastic = varibad["final"].pop("stochastic")
    path.write_text(json.dumps(record))
    varibad_path.write_text(json.dumps(varibad))
    proc = run(
        "--agents oracle varibad --tasks cheetah_dir_sparse --seeds 0 1 --frames 400 --eval-every 200 "
        f"--eval-tasks 4 --workers 2 --config {tiny_config} --out {out} --no-progress --resume".split()
    )
    assert proc.returncode == 0, proc.stderr
    again = json.loads(path.read_text())["final"]["certainty_equivalent"]
    assert again["online_return_per_task"] == pytest.approx(expected["online_return_per_task"])
    refit = json.loads(varibad_path.read_text())["final"]
    assert refit["probe_kl_per_step"] == pytest.approx(expected_kl, rel=1e-5, abs=1e-7)
    assert refit["probe_kl"] == pytest.approx(varibad["final"]["probe_kl"], rel=1e-5, abs=1e-7)
    assert refit["turned_around"] == expected_turned  # None where no deployment was wrong first
    assert refit["stochastic"]["online_return_per_task"] == pytest.approx(expected_stochastic["online_return_per_task"])
    results = {(r["agent"], r["seed"]): r for r in json.loads((out / "results.json").read_text())}
    assert results[("task_aware", 0)]["final"]["certainty_equivalent"]["online_return"] == again["online_return"]


@pytest.mark.parametrize(
    "args,message",
    [
        (["--agents", "orakel", "--tasks", "cheetah_dir_sparse"], "unknown agent 'orakel'"),
        (["--agents", "oracle", "--tasks", "cheetah_sparse"], "unknown task 'cheetah_sparse'"),
        (["--agents", "oracle", "--tasks", "cheetah_dir", "--frames", "0"], "--frames must be positive"),
        (["--agents", "oracle", "--tasks", "cheetah_dir", "--video-tasks", "0"], "--video-tasks must be positive"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(tmp_path, args, message):
    argv = args + (["--frames", "100"] if "--frames" not in args else []) + ["--out", tmp_path / "o"]
    proc = run(argv)
    assert proc.returncode == 2
    assert message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_bad_config_field_and_foreign_out_dir(tmp_path, tiny_config):
    bad = tmp_path / "bad.toml"
    bad.write_text('[oracle]\n"ppo.lrr" = 0.1\n')
    proc = run(
        ["--agents", "oracle", "--tasks", "cheetah_dir", "--frames", 100, "--config", bad, "--out", tmp_path / "o"]
    )
    assert proc.returncode == 2 and "ppo.lrr" in proc.stderr and "did you mean ppo.lr" in proc.stderr
    typo = tmp_path / "typo.toml"
    typo.write_text('[orcale]\n"ppo.lr" = 0.1\n')
    proc = run(
        ["--agents", "oracle", "--tasks", "cheetah_dir", "--frames", 100, "--config", typo, "--out", tmp_path / "o"]
    )
    assert proc.returncode == 2 and "unknown agents: orcale" in proc.stderr
    out = tmp_path / "grid"
    grid = f"--agents oracle --tasks cheetah_dir --config {tiny_config} --no-reference --eval-tasks 2 --out {out}"
    args = [*grid.split(), "--no-progress", "--frames", "200"]
    assert run(args).returncode == 0
    before = (out / "results.json").read_bytes()
    other = run([*args[:-1], "400"])  # a different grid (more frames) in the same --out
    assert other.returncode == 2 and "different grid" in other.stderr
    again = run(args)  # the same grid without --resume
    assert again.returncode == 2 and "--resume" in again.stderr
    assert (out / "results.json").read_bytes() == before
    resumed = run(args + ["--resume"])  # nothing left to do: completed cells are kept
    assert resumed.returncode == 0
    assert strip_times(json.loads((out / "results.json").read_text())) == strip_times(json.loads(before))


def test_sigkill_then_resume_equals_uninterrupted_run(tmp_path, tiny_config):
    args = (
        "--agents varibad --tasks cheetah_dir_sparse --seeds 3 --frames 2000 --eval-every 200 --eval-tasks 2 "
        f"--config {tiny_config} --no-reference --no-progress"
    ).split()
    assert run(args + ["--out", tmp_path / "whole"]).returncode == 0

    out = tmp_path / "killed"
    env = {**os.environ, "MUJOCO_GL": "disable"}
    proc = subprocess.Popen(
        RUN + [str(a) for a in args] + ["--out", str(out)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    record = out / "cells" / "varibad__cheetah_dir_sparse__s3" / "record.json"
    deadline = time.time() + 300
    while time.time() < deadline:  # kill once two evaluation points are on disk, mid-training
        if record.exists() and len(json.loads(record.read_text())["curve"]) >= 2:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    partial = json.loads(record.read_text())
    assert not partial["complete"] and 2 <= len(partial["curve"]) < 10
    whole = json.loads((tmp_path / "whole" / "results.json").read_text())
    # The worst moment for the kill, made certain: the record already holds the point after the checkpoint
    # (written, then killed before its checkpoint). The resumed run must evaluate it again, so that the next
    # point still averages only its own iterations (reward_share, advantage_std).
    iteration = serialization.load(record.parent / "checkpoint.pt", kind="checkpoint")["iteration"]
    assert 1 <= iteration <= 8, iteration  # two iterations left after the doctored point, so it would show
    partial["curve"] = [p for p in whole[0]["curve"] if p["frames"] <= (iteration + 1) * 200]
    record.write_text(json.dumps(partial))
    resumed = run(args + ["--out", out, "--resume"])
    assert resumed.returncode == 0, resumed.stderr
    again = json.loads((out / "results.json").read_text())
    assert strip_times(again) == strip_times(whole)


class Crash(Exception):
    """A simulated crash of a cell's process."""


def test_resume_from_a_checkpoint_between_evaluation_points_keeps_each_points_averages(tmp_path):
    """A crash after a periodic checkpoint that falls between two evaluation points: the resumed cell's next
    point must still average the reward shares and advantage spreads of all its own iterations, those
    before the checkpoint included, as the uninterrupted cell's does."""
    from hyperstate.evaluation.cell import CellSpec, run_cell

    # The tiny grid's settings (200 frames per iteration), a point every 3 iterations, a checkpoint after each.
    overrides = {**tomllib.loads(TINY_CONFIG)["all"], "checkpoint_every": 1}

    def spec(out: Path, resume: bool) -> CellSpec:
        return CellSpec(
            agent="hyperx",
            task="cheetah_dir_sparse",
            seed=1,
            frames=1800,
            eval_every=600,
            eval_tasks=2,
            episodes_per_task=None,
            overrides=overrides,
            out=str(out),
            resume=resume,
        )

    whole = run_cell(spec(tmp_path / "whole", resume=False))
    calls = []

    def crash_at_iteration_5() -> None:  # called before iteration 5's bookkeeping: iteration 4 is checkpointed
        calls.append(1)
        if len(calls) == 5:
            raise Crash

    with pytest.raises(Crash):
        run_cell(spec(tmp_path / "crashed", resume=False), sync=crash_at_iteration_5)
    cell = tmp_path / "crashed" / "cells" / "hyperx__cheetah_dir_sparse__s1"
    assert serialization.load(cell / "checkpoint.pt", kind="checkpoint")["iteration"] == 4
    assert [p["frames"] for p in json.loads((cell / "record.json").read_text())["curve"]] == [600]
    resumed = run_cell(spec(tmp_path / "crashed", resume=True))
    assert [p["frames"] for p in resumed["curve"]] == [600, 1200, 1800]
    assert set(whole["curve"][1]["reward_share"]) == {"extrinsic", "0_rnd_hyperstate", "1_rnd_state"}
    assert strip_times([resumed]) == strip_times([whole])


def test_ray_on_two_nodes_without_a_shared_out_survives_a_dead_node(tmp_path, tiny_config):
    """A simulated two-node Ray cluster whose cells work in their own node's folders and keep checkpoints
    in a storage apart from the driver's --out: the node running the cells dies mid-grid, a new node
    joins, the cells resume there from the storage, and every number equals the local executor's. The
    agent is a user-registered preset (--import): Ray cells import the driver's copy of the user's file."""
    from ray.cluster_utils import Cluster

    user = tmp_path / "user_presets.py"
    user.write_text(
        'from hyperstate import agents\nagents.register_preset("user_oracle", agents.get_preset("oracle"))\n'
    )
    args = (
        f"--import {user} --agents user_oracle --tasks cheetah_dir --seeds 0 1 --frames 1000 --eval-every 200 "
        f"--eval-tasks 2 --no-reference --config {tiny_config} --no-progress"
    ).split()
    local = run(args + ["--out", tmp_path / "local", "--workers", "2"])
    assert local.returncode == 0, local.stderr[-2000:]

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0})  # the driver's node runs no cell
    try:
        doomed = cluster.add_node(num_cpus=2)
        out, storage = tmp_path / "ray_out", tmp_path / "storage"
        driver = subprocess.Popen(
            RUN
            + args
            + ["--executor", "ray", "--ray-address", cluster.address, "--out", str(out)]
            + ["--storage", str(storage)],
            env={**os.environ, "MUJOCO_GL": "disable"},
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        records = [storage / "cells" / f"user_oracle__cheetah_dir__s{seed}" / "record.json" for seed in (0, 1)]

        def curve_lengths() -> list[int]:
            lengths = []
            for path in records:
                record = json.loads(path.read_text()) if path.exists() else {"curve": [], "complete": False}
                lengths.append(-1 if record["complete"] else len(record["curve"]))
            return lengths

        deadline = time.time() + 400
        while time.time() < deadline and not any(n >= 1 for n in curve_lengths()):
            time.sleep(0.1)  # kill the node once a cell has a checkpoint in the storage, mid-training
        cluster.remove_node(doomed)
        interrupted = [n for n in curve_lengths() if n >= 1]
        assert interrupted, "the node died before any cell had checkpointed (or after all finished)"
        cluster.add_node(num_cpus=2)
        stdout, stderr = driver.communicate(timeout=600)
        assert driver.returncode == 0, stderr[-3000:]
    finally:
        cluster.shutdown()
    ray_results = json.loads((out / "results.json").read_text())
    assert len(ray_results) == 2 and all(r["complete"] for r in ray_results)
    assert strip_times(ray_results) == strip_times(json.loads((tmp_path / "local" / "results.json").read_text()))
    # The driver's --out got every cell's files from the cells' returns, the checkpoints stayed in storage.
    for seed in (0, 1):
        cell = out / "cells" / f"user_oracle__cheetah_dir__s{seed}"
        assert {"record.json", "agent.pt", "deployment.npz"} <= {p.name for p in cell.iterdir()}
        assert len(list((cell / "snapshots").glob("agent_*.pt"))) == 5
        assert not (cell / "checkpoint.pt").exists()
        assert (storage / "cells" / cell.name / "checkpoint.pt").exists()
        assert any((out / "tb" / cell.name).glob("events.out.tfevents.*"))


def test_ray_cells_import_the_drivers_copy_of_import_files(tmp_path):
    """A Ray cell's node need not have the user's --import files: the driver ships their sources, and the
    cell imports a copy under the same module name."""
    from hyperstate.evaluation.imports import materialize_imports, read_import_sources

    user = tmp_path / "shipped_user_presets.py"
    user.write_text(
        'from hyperstate import agents\nagents.register_preset("shipped_oracle", agents.get_preset("oracle"))\n'
    )
    sources = read_import_sources([str(user), "json"])
    assert sources == ((str(user), user.read_text()),)  # modules by name are the node's own
    user.unlink()  # the node running the cell has no copy
    imports = materialize_imports((str(user), "json"), sources)
    copy = Path(imports[0])
    assert imports[1] == "json" and copy.name == user.name and copy.read_text() == sources[0][1]
    check = (
        "import sys; from hyperstate.evaluation.imports import import_modules; import_modules(sys.argv[1:]); "
        "from hyperstate import agents; print(agents.get_preset('shipped_oracle').belief)"
    )
    proc = subprocess.run([sys.executable, "-c", check, *imports], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "oracle"
    # The same source lands on the same file (a worker running several cells imports it once); another
    # source never reuses it.
    assert materialize_imports((str(user),), sources) == imports[:1]
    edited = ((str(user), sources[0][1] + "# edited\n"),)
    assert materialize_imports((str(user),), edited) != imports[:1]


def test_cell_store_copies_the_checkpoint_last_and_only_what_changed(tmp_path):
    """A node dying mid-copy must never leave a stored checkpoint ahead of the stored record and
    snapshots (a resumed cell would skip their evaluation points)."""
    from hyperstate.evaluation.storage import CellStore

    cell, work, storage = "a__t__s0", tmp_path / "work", tmp_path / "storage"
    folder = work / "cells" / cell
    (folder / "snapshots").mkdir(parents=True)
    for name in ("checkpoint.pt", "record.json", "coverage.npy", "snapshots/agent_000000200.pt"):
        (folder / name).write_text(name)
    (work / "tb" / cell).mkdir(parents=True)
    (work / "tb" / cell / "events").write_text("e")
    store = CellStore(str(storage), cell)
    order = [str(p.relative_to(work)) for p in store.local_files(work)]
    assert order[-2:] == [f"cells/{cell}/record.json", f"cells/{cell}/checkpoint.pt"] and len(order) == 5
    assert store.push(work) == 5 and store.push(work) == 0  # unchanged files are not copied again
    (folder / "record.json").write_text("newer record")
    assert store.push(work) == 1
    # A copy a dying node left unfinished is ignored; the rest comes back.
    (storage / "cells" / cell / "checkpoint.pt.part").write_text("half")
    again = tmp_path / "again"
    pulled = CellStore(str(storage), cell).pull(again)
    assert sorted(pulled) == sorted(order) and (again / "cells" / cell / "record.json").read_text() == "newer record"


def test_ray_storage_must_be_empty_unless_resuming(tmp_path):
    (tmp_path / "storage" / "cells" / "some_cell").mkdir(parents=True)
    common = f"--agents oracle --tasks cheetah_dir --frames 200 --executor ray --storage {tmp_path / 'storage'}"
    proc = run(f"{common} --out {tmp_path / 'out'}".split())
    assert proc.returncode == 2 and "holds cells of an earlier run" in proc.stderr
    proc = run(f"--agents oracle --tasks cheetah_dir --frames 200 --storage {tmp_path} --out {tmp_path / 'o'}".split())
    assert proc.returncode == 2 and "local executor works in --out" in proc.stderr


# Beyond the paper: coverage, belief probe, Bayes-optimal estimate -----------------------------------
def test_hyperstate_coverage_known_cases():
    from hyperstate.evaluation.coverage import HyperStateCoverage

    still = HyperStateCoverage.for_task("cheetah_dir_sparse")
    still.update({"x_displacement": np.full((200, 4, 1), 0.3), "belief": np.full((200, 4, 2), 0.5)})
    assert still.fraction() == pytest.approx(1 / (40 * 3))  # a policy that stands still covers one cell
    sweep = HyperStateCoverage.for_task("cheetah_dir_sparse")
    x = np.linspace(-19.9, 19.9, 400)[:, None, None]
    sweep.update({"x_displacement": x, "belief": np.tile([0.0, 1.0], (400, 1, 1))})
    assert sweep.visited[:, 2].all() and not sweep.visited[:, :2].any()
    sweep.update({"x_displacement": x, "belief": np.tile([0.5, 0.5], (400, 1, 1))})
    assert sweep.fraction() == pytest.approx(2 / 3)


def _exact_beliefs(t_len=60, m=20, seed=0):
    rng = np.random.default_rng(seed)
    forward = (np.arange(m) // 2) % 2  # the probe's train (even) and test (odd) halves both see each task
    reveal = rng.integers(10, 50, m)
    exact = np.full((t_len, m, 2), 0.5)
    for i in range(m):
        exact[reveal[i] :, i] = np.eye(2)[forward[i]]
    return exact


def test_belief_probe_is_perfect_on_the_exact_belief_and_blind_without_features():
    from hyperstate.evaluation.probe import belief_quality

    exact = _exact_beliefs()
    perfect = belief_quality(exact + 1e-3 * np.random.default_rng(1).normal(size=exact.shape), exact)
    assert perfect["probe_kl_after"] < 0.05 and perfect["probe_accuracy_after"] == 1.0
    assert perfect["probe_kl_before"] < 0.05  # the prior is recognised as the prior too
    # Per step of the BAMDP: no test deployment is informed before step 10, all are by step 50.
    assert len(perfect["probe_kl_per_step"]) == 60 and max(perfect["probe_kl_per_step"]) < 0.05
    assert perfect["probe_accuracy_per_step"][:10] == [None] * 10
    assert all(a in (None, 1.0) for a in perfect["probe_accuracy_per_step"][10:50])
    assert perfect["probe_accuracy_per_step"][50:] == [1.0] * 10
    blind = belief_quality(np.zeros((*exact.shape[:2], 0)), exact)  # e.g. the Markov agent: no features
    # It can only guess the marginal (0.5, 0.5): right before any reveal, ln 2 nats off once revealed.
    assert blind["probe_kl_after"] == pytest.approx(np.log(2), abs=0.02)
    assert blind["probe_kl_per_step"][0] < 0.01 and blind["probe_kl_per_step"][-1] == pytest.approx(np.log(2), abs=0.02)
    assert 0.0 < blind["informed_fraction"] == perfect["informed_fraction"] < 1.0


def test_bayes_optimal_estimate_by_hand():
    from hyperstate.suite.cheetah_dir import bayes_optimal_estimate

    got = bayes_optimal_estimate(np.array([300.0, 50.0, -10.0]), zone_radius=5.0)
    assert got == pytest.approx(((300 - 100) + (50 - 25) + (-10)) / 3)  # detour 2 * 5 m / 0.05 s = 200
    # The report asks the task: only cheetah-direction tasks define the estimate.
    assert suite.bayes_estimate("cheetah_dir_sparse")([300.0]) == pytest.approx(200.0)


class _GaitFollower:
    """A 'task-aware' agent: runs the scripted gait of whatever task it is shown; logs what it saw."""

    def __init__(self):
        self.shown = []

    def act(self, obs, state=None, deterministic=True, reward=None):
        step = 0 if state is None else state
        self.shown.append(obs["task"][:, 0].copy())
        action = np.stack([gait(float(d))(step) for d in obs["task"][:, 0]])
        return action, step + 1

    def belief_features(self, state):
        return np.zeros((2, 0))


def test_certainty_equivalent_shows_the_belief_mode_and_pays_the_wrong_guess():
    from hyperstate.evaluation.deploy import CertaintyEquivalent

    follower = _GaitFollower()
    support = suite.task_prior("cheetah_dir_sparse").support()  # rows [backward], [forward]
    tasks = np.array([[BACKWARD], [FORWARD]])
    d = deploy(CertaintyEquivalent(follower, support), "cheetah_dir_sparse", tasks)
    shown = np.stack(follower.shown)  # (T, 2)
    x = d.observations["x_displacement"][..., 0]
    # Until the first step ending outside the zone the belief is the prior: the tie goes to support[0].
    exit_step = int(np.argmax(np.abs(x[:, 1]) >= 5.0))
    assert np.all(shown[: exit_step + 1] == BACKWARD)
    assert np.all(shown[exit_step + 1 :, 1] == FORWARD) and np.all(shown[:, 0] == BACKWARD)
    assert x[exit_step, 1] <= -5.0  # the forward task's wrong guess left the zone backward
    # A correct first guess costs nothing: the backward task earns what the true-task agent earns.
    truthful = deploy(_GaitFollower(), "cheetah_dir_sparse", tasks)
    assert d.rewards[:, 0].sum() == pytest.approx(truthful.rewards[:, 0].sum())
    assert d.rewards[:, 1].sum() < truthful.rewards[:, 1].sum()  # the detour is paid


def _script_agents(script: str) -> list[str]:
    import re

    text = (ROOT / "scripts" / script).read_text()
    listed = re.search(r"AGENTS:-([^}]*)}", text)
    return listed.group(1).split() if listed else text.split("--agents")[1].split("--tasks")[0].split()


@pytest.mark.parametrize(
    "script,folder", [("reproduce_fig2_turnaround.sh", "fig2_turnaround"), ("reproduce_fig2_icml.sh", "fig2_icml")]
)
def test_reproduce_scripts_run_the_presets_as_they_are_at_the_committed_grids_settings(script, folder):
    """scripts/: the published grids are plain harness calls (no --config, no --import) whose agents are the
    committed cells' agents (tests/test_presets.py) at the committed grid's budget and evaluation points."""
    from hyperstate.evaluation.run import build_grid, parse_args

    text = (ROOT / "scripts" / script).read_text()
    command = text[text.index("evaluation/run.py") :]
    assert "--config" not in command and "--import" not in command
    names = _script_agents(script)
    sources = json.loads((ROOT / "docs" / "results" / folder / "sources.json").read_text())
    assert {cell.split("__")[0] for cell in sources} == set(names)
    budgets = {(s["budget"], s["eval_every"], s["eval_tasks"]) for s in sources.values()}
    eval_every = int(command.split("--eval-every ")[1].split()[0])
    assert budgets == {(20_000_000, eval_every, 20)} and "FRAMES=${1:-20000000}" in text
    args = parse_args(["--agents", *names, "--tasks", "cheetah_dir_sparse", "--frames", "2e7", "--out", "unused",
                       "--no-reference"])  # fmt: skip
    built, overrides = build_grid(args)
    assert built == names and all(o == {} for o in overrides.values())


@pytest.mark.parametrize("path", sorted((ROOT / "research" / "catalogue").glob("*.toml")), ids=lambda p: p.stem)
def test_catalogue_overlays_change_one_named_setting_the_same_on_every_calibration_agent(path):
    """research/catalogue/*.toml (calibrate.sh's CONFIG): one [all] table, so every agent of a calibration gets
    the same per-task setting, and each field it names reaches the built agent with that value."""
    import tomllib

    from hyperstate.evaluation.run import build_grid, parse_args

    tables = tomllib.loads(path.read_text())
    assert list(tables) == ["all"] and tables["all"]
    names = ["hyperx", "oracle_rh", "oracle", "varibad_rh", "varibad"]
    args = parse_args(["--agents", *names, "--tasks", "point_robot_sparse", "--frames", "2e7", "--out", "unused",
                       "--no-reference", "--config", str(path)])  # fmt: skip
    built, overrides = build_grid(args)
    assert built == names and all(o == tables["all"] for o in overrides.values())

    def field(config, key):
        for part in key.split("."):
            config = getattr(config, part)
        return config

    for name in names:
        changed, plain = agents.make(name, **overrides[name]).config, agents.make(name).config
        for key, value in tables["all"].items():
            assert field(changed, key) == value != field(plain, key), (name, key)
    assert '--config "$CONFIG"' in (ROOT / "research" / "catalogue" / "calibrate.sh").read_text()


CAMPAIGN = ROOT / "research" / "turnaround"


def _campaign_agent(name: str, overrides: dict):
    """The campaign's agent of that name: its presets were the seed paper's, today's `_paper` ones."""
    return agents.make(f"{name}_paper" if name in agents.GRID_PRESETS else name, **overrides).config


@pytest.mark.parametrize("path", sorted((CAMPAIGN / "configs").glob("*.toml")), ids=lambda p: p.stem)
def test_campaign_configs_change_what_they_say_on_the_campaigns_agents(path):
    """Each overlay of the turn-around campaign (research/turnaround/notebook.md) names real fields and changes
    them on top of research/turnaround/fig2.toml: its [all] table on `oracle_rh`, a preset's table on it."""
    import tomllib

    from hyperstate.evaluation.imports import import_modules

    registered = set(agents.PRESETS)
    import_modules([str(CAMPAIGN / "fig2_presets.py"), str(CAMPAIGN / "campaign_presets.py")])
    try:
        base, tables = tomllib.loads((CAMPAIGN / "fig2.toml").read_text()), tomllib.loads(path.read_text())
        agent = next((name for name in tables if name != "all"), "oracle_rh")
        plain = {**base.get("all", {}), **base.get(agent, {})}
        changed = {**plain, **tables.get("all", {}), **tables.get(agent, {})}
        config = _campaign_agent(agent, changed)
        added = {k: v for k, v in changed.items() if plain.get(k) != v}
        assert added, f"{path.name} changes nothing"
        for key, value in added.items():
            node = config
            for part in key.split("."):
                node = node[int(part)] if part.isdigit() else getattr(node, part)
            assert node == value, key
    finally:
        for name in set(agents.PRESETS) - registered:  # whatever the imported files registered
            agents.unregister_preset(name)
        for module in ("fig2_presets", "campaign_presets"):
            sys.modules.pop(module, None)


def test_campaign_turnaround_settings_on_the_paper_presets_are_the_validated_presets():
    """The campaign's last grid (seed presets + fig2.toml + four overlays) is what the presets now are: the
    research's path from the seed paper's agents to the published ones, checked field for field."""
    import tomllib

    overlays = ["lr_horizon_5e7", "icml_ppo", "reference_network", "hyperstate_weight_20"]
    tables = [tomllib.loads((CAMPAIGN / "fig2.toml").read_text())]
    tables += [tomllib.loads((CAMPAIGN / "configs" / f"{o}.toml").read_text()) for o in overlays]
    for name in agents.GRID_PRESETS:
        overrides = {}
        for table in tables:
            overrides.update({**table.get("all", {}), **table.get(name, {})})
        assert agents.agent_settings(_campaign_agent(name, overrides)) == agents.agent_settings(agents.get_preset(name))


def test_grid_layout_owns_cell_names_and_paths(tmp_path):
    from hyperstate.evaluation import grid

    cell = grid.cell_id("oracle_rh", "cheetah_dir_sparse", 12)
    assert cell == "oracle_rh__cheetah_dir_sparse__s12"
    assert grid.parse_cell_id(cell) == ("oracle_rh", "cheetah_dir_sparse", 12)
    assert grid.record_cell_id({"agent": "a", "task": "t", "seed": 0}) == "a__t__s0"
    for bad in ("oracle__cheetah", "a__b__seed1", "a__b__c__s1"):
        with pytest.raises(ValueError, match="not a cell id"):
            grid.parse_cell_id(bad)
    assert grid.cell_ids(tmp_path) == []
    for frames in (2000, 1000):
        path = grid.snapshot_path(tmp_path, cell, frames)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("x")
    assert grid.cell_ids(tmp_path) == [cell]
    assert [f for f, _ in grid.snapshots(tmp_path, cell)] == [1000, 2000]


def test_grid_progress_view_plain_and_live(tmp_path, monkeypatch):
    import io

    from hyperstate.evaluation import grid, progress
    from hyperstate.files import write_json_atomic

    cells = [grid.cell_id("oracle", "cheetah_dir_sparse", s) for s in (0, 1)]
    state = {"frames": 400_000, "total_frames": 2_000_000, "fps": 6123.0, "wall_seconds": 65.0,
             "online_return": 12.5, "return_frames": 200_000, "eta_seconds": 260.0, "complete": False}  # fmt: skip
    grid.cell_dir(tmp_path, cells[0]).mkdir(parents=True)
    write_json_atomic(grid.cell_dir(tmp_path, cells[0]) / grid.PROGRESS, state)
    monkeypatch.setattr(progress, "PLAIN_EVERY_SECONDS", 0.0)
    plain = io.StringIO()
    view = progress.GridProgress(tmp_path, cells, stream=plain)
    view.poll()
    view.cell_done(cells[0])
    lines = plain.getvalue().splitlines()
    assert lines[0] == (
        f"[grid 0/2 done] {cells[0]}  0.40M/2.00M frames  6,123 frames/s  online return 12.5 (at 0.20M)  ETA 4 min"
    )
    assert lines[1] == f"[grid 1/2 done] {cells[0]} done: online return 12.5 after 1.1 min" and len(lines) == 2
    assert "\r" not in plain.getvalue()  # no carriage-return bars in logs

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    live = Terminal()
    view = progress.GridProgress(tmp_path, cells, stream=live)
    view.poll()
    assert cells[0] in live.getvalue() and "6,123" in live.getvalue()
    view.cell_done(cells[0])
    view.close()
    quiet = io.StringIO()
    progress.GridProgress(tmp_path, cells, enabled=False, stream=quiet).poll()
    assert quiet.getvalue() == ""


def test_cells_report_progress_and_draw_nothing(tmp_path, tiny_config):
    out = tmp_path / "grid"
    proc = run(
        f"--agents oracle --tasks cheetah_dir_sparse --seeds 0 1 --frames 400 --eval-tasks 2 --no-reference "
        f"--config {tiny_config} --workers 2 --out {out}".split()
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    done = [line for line in proc.stderr.splitlines() if line.startswith("[grid ")]
    assert sorted(line.split()[3] for line in done) == [
        "oracle__cheetah_dir_sparse__s0",
        "oracle__cheetah_dir_sparse__s1",
    ]
    assert "\r" not in proc.stderr  # not a terminal: no bars, from the cells or the driver
    for seed in (0, 1):
        state = json.loads((out / "cells" / f"oracle__cheetah_dir_sparse__s{seed}" / "progress.json").read_text())
        assert state["complete"] and state["frames"] == 400 and state["total_frames"] == 400


def test_several_config_files_merge_in_order(tmp_path):
    from hyperstate.evaluation.run import build_grid, parse_args

    base, change = tmp_path / "base.toml", tmp_path / "change.yaml"
    base.write_text('[all]\n"ppo.num_envs" = 8\n"ppo.entropy_coef" = 0.01\n[oracle_rh]\n"bonuses.0.buffer_size" = 5\n')
    change.write_text("all:\n  ppo.entropy_coef: 0.001\noracle_rh:\n  bonuses.0.weight: 3.0\n")
    args = parse_args(
        ["--agents", "oracle_rh", "--tasks", "cheetah_dir_sparse", "--frames", "100", "--out", str(tmp_path / "o"),
         "--config", str(base), str(change), "--no-reference"]
    )  # fmt: skip
    _, overrides = build_grid(args)
    assert overrides["oracle_rh"] == {
        "ppo.num_envs": 8,
        "ppo.entropy_coef": 0.001,
        "bonuses.0.buffer_size": 5,
        "bonuses.0.weight": 3.0,
    }


def test_merge_gathers_grids_run_in_parts_and_refuses_parts_of_other_experiments(tmp_path, tiny_config, capsys):
    """A grid run in parts (other seeds, other sessions) merges into one report; a part trained with another
    config or budget is refused; unfinished cells are left out; merging again changes nothing."""
    import shutil

    from hyperstate.evaluation.merge import main as merge_main

    common = "--agents oracle --tasks cheetah_dir_sparse --frames 400 --eval-every 200 --eval-tasks 4 --no-reference "
    common += "--workers 1 --no-progress --config"
    other = tmp_path / "other.toml"
    other.write_text(TINY_CONFIG + '"ppo.entropy_coef" = 0.5\n')
    parts = {}
    for name, seed, config in (("a", 0, tiny_config), ("b", 1, tiny_config), ("c", 2, other)):
        parts[name] = tmp_path / name
        proc = run(f"{common} {config} --seeds {seed} --out {parts[name]}".split())
        assert proc.returncode == 0, proc.stderr[-2000:]
    into = tmp_path / "merged"
    assert merge_main([str(parts["a"]), str(parts["b"]), "--into", str(into)]) == 0
    merged = {r["seed"]: r for r in json.loads((into / "results.json").read_text())}
    for seed, part in ((0, parts["a"]), (1, parts["b"])):
        (source,) = json.loads((part / "results.json").read_text())
        assert merged[seed] == source
        cell = into / "cells" / f"oracle__cheetah_dir_sparse__s{seed}"
        assert sorted(p.name for p in cell.iterdir()) == ["coverage.npy", "deployment.npz", "record.json"]
    with (into / "summary.csv").open() as f:
        (row,) = list(csv.DictReader(f))
    assert row["seeds"] == "2"
    assert float(row["online_return_mean"]) == pytest.approx(
        np.mean([r["final"]["online_return"] for r in merged.values()])
    )
    assert (into / "figures" / "curves_cheetah_dir_sparse.png").read_bytes()[:4] == b"\x89PNG"
    assert (into / "figures" / "behaviour_oracle__cheetah_dir_sparse__s0.png").exists()
    sources = json.loads((into / "sources.json").read_text())
    assert sources["oracle__cheetah_dir_sparse__s1"]["source"] == str(parts["b"])
    assert sources["oracle__cheetah_dir_sparse__s1"]["budget"] == 400
    assert sources["oracle__cheetah_dir_sparse__s1"]["overrides"]["ppo.num_envs"] == 4
    (command,) = sources["oracle__cheetah_dir_sparse__s1"]["commands"]
    assert command.endswith(f"--seeds 1 --out {parts['b']}")
    before = (into / "results.json").read_text()

    # Another config for the same agent: refused, naming the field, and nothing written.
    assert merge_main([str(parts["c"]), "--into", str(into)]) == 2
    assert (into / "results.json").read_text() == before and not (
        into / "cells" / "oracle__cheetah_dir_sparse__s2"
    ).exists()
    # Another budget (the part's grid asked for more frames): refused.
    longer = tmp_path / "longer"
    shutil.copytree(parts["a"], longer)
    shutil.move(
        longer / "cells" / "oracle__cheetah_dir_sparse__s0", longer / "cells" / "oracle__cheetah_dir_sparse__s3"
    )
    record_path = longer / "cells" / "oracle__cheetah_dir_sparse__s3" / "record.json"
    record = json.loads(record_path.read_text())
    record["seed"] = 3
    record_path.write_text(json.dumps(record))
    grid_args = json.loads((longer / "grid.json").read_text())
    (longer / "grid.json").write_text(json.dumps({**grid_args, "frames": 800}))
    assert merge_main([str(longer), "--into", str(into)]) == 2
    assert "training budgets differ" in capsys.readouterr().err
    # The same budget: seed 3 joins; an unfinished cell beside it is left out.
    (longer / "grid.json").write_text(json.dumps(grid_args))
    unfinished = longer / "cells" / "oracle__cheetah_dir_sparse__s4"
    unfinished.mkdir()
    (unfinished / "record.json").write_text(json.dumps({**record, "seed": 4, "complete": False, "final": None}))
    assert merge_main([str(longer), "--into", str(into)]) == 0
    assert sorted(r["seed"] for r in json.loads((into / "results.json").read_text())) == [0, 1, 3]
    # Merging a part again changes nothing; the same cell with other results needs --replace.
    assert merge_main([str(parts["b"]), "--into", str(into)]) == 0
    changed = json.loads((parts["b"] / "cells" / "oracle__cheetah_dir_sparse__s1" / "record.json").read_text())
    changed["final"]["online_return"] += 1.0
    (parts["b"] / "cells" / "oracle__cheetah_dir_sparse__s1" / "record.json").write_text(json.dumps(changed))
    assert merge_main([str(parts["b"]), "--into", str(into)]) == 2
    assert merge_main([str(parts["b"]), "--into", str(into), "--replace"]) == 0
    merged = {r["seed"]: r for r in json.loads((into / "results.json").read_text())}
    assert merged[1]["final"]["online_return"] == changed["final"]["online_return"]


def test_merge_takes_some_agents_from_committed_grids_and_keeps_where_each_cell_came_from(
    tmp_path, tiny_config, capsys
):
    """`--agents` pools some agents' seeds out of merged (committed) grids; a cell merged twice keeps its
    first source, git commit and grid arguments, with `via` naming the merged grid it passed through."""
    from hyperstate.evaluation.merge import main as merge_main

    common = "--tasks cheetah_dir_sparse --frames 400 --eval-every 200 --eval-tasks 4 --no-reference "
    common += f"--workers 1 --no-progress --config {tiny_config}"
    two, one = tmp_path / "two_agents", tmp_path / "more_seeds"
    for out, spec in ((two, "--agents oracle ppo --seeds 0"), (one, "--agents oracle --seeds 1")):
        proc = run(f"{spec} {common} --out {out}".split())
        assert proc.returncode == 0, proc.stderr[-2000:]
    committed = tmp_path / "committed"
    assert merge_main([str(two), "--into", str(committed)]) == 0
    pooled = tmp_path / "pooled"
    assert merge_main([str(committed), str(one), "--agents", "oracle", "--into", str(pooled)]) == 0
    assert sorted(p.name for p in (pooled / "cells").iterdir()) == [
        "oracle__cheetah_dir_sparse__s0",
        "oracle__cheetah_dir_sparse__s1",
    ]
    sources = json.loads((pooled / "sources.json").read_text())
    first = json.loads((committed / "sources.json").read_text())["oracle__cheetah_dir_sparse__s0"]
    assert sources["oracle__cheetah_dir_sparse__s0"] == {**first, "via": str(committed)}
    assert first["source"] == str(two) and first["budget"] == 400
    assert "via" not in sources["oracle__cheetah_dir_sparse__s1"]
    with (pooled / "summary.csv").open() as f:
        (row,) = list(csv.DictReader(f))
    assert (row["agent"], row["seeds"]) == ("oracle", "2")
    # An agent none of the parts has: refused, nothing written.
    assert merge_main([str(committed), "--agents", "hyperx", "--into", str(tmp_path / "none")]) == 2
    assert not (tmp_path / "none").exists()
    # --agents before a part folder would take the folder for an agent: refused with a one-line error.
    with pytest.raises(SystemExit) as exit_info:
        merge_main([str(committed), "--agents", "oracle", str(one), "--into", str(tmp_path / "none")])
    assert exit_info.value.code == 2 and not (tmp_path / "none").exists()
    assert f"took the part folder {one} for an agent name" in capsys.readouterr().err


@pytest.mark.parametrize(
    "task,oracles", [("rooms_sparse", True), ("point_robot_sparse", False), ("mountain_treasure_k8_sparse", True)]
)
def test_the_catalogue_script_runs_the_issues_agents_and_the_oracles_where_the_task_has_an_exact_belief(task, oracles):
    """scripts/reproduce_catalogue.sh: the meta-learners and the task-aware reference on every task, the
    belief oracles where the task has a privileged `belief`; 3 seeds, 20 held-out tasks, 10 points; a
    harness call that parses and builds with the presets as they are."""
    from hyperstate.evaluation.run import build_grid, parse_args

    env = {k: v for k, v in os.environ.items() if k not in ("AGENTS", "SEEDS", "CONFIG", "EVAL_EVERY")}
    proc = subprocess.run(["bash", str(ROOT / "scripts" / "reproduce_catalogue.sh"), task, "2e7"],
                          capture_output=True, text=True, env={**env, "DRY_RUN": "1"}, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    command = proc.stdout.split()
    args = command[command.index("evaluation/run.py") + 1 :]
    expected = ["hyperx", "varibad_rh", "varibad", "rl2", "task_supervised", "task_aware"]
    expected += ["oracle", "oracle_rh", "oracle_rs"] if oracles else []
    assert args[args.index("--agents") + 1 : args.index("--tasks")] == expected
    assert args[args.index("--seeds") + 1 : args.index("--frames")] == ["0", "1", "2"]
    assert args[args.index("--eval-every") + 1] == "2000000" and args[args.index("--eval-tasks") + 1] == "20"
    built, overrides = build_grid(parse_args(args))
    assert built == expected and all(o == {} for o in overrides.values())


def test_a_catalogue_lane_runs_its_parts_in_order_each_in_its_own_folder_evaluated_every_1m_frames():
    """research/catalogue/lane.sh: one reproduce_catalogue.sh call per "AGENTS|SEEDS" part, in order, each
    its own OUT under runs/<task>/, with the calibrations' evaluation points (so their seed-0 cells merge);
    a malformed part is refused before anything runs."""
    env = {k: v for k, v in os.environ.items() if k not in ("AGENTS", "SEEDS", "CONFIG", "EVAL_EVERY")}
    lane = ["bash", str(ROOT / "research" / "catalogue" / "lane.sh"), "rooms_sparse", "5e7"]
    proc = subprocess.run([*lane, "oracle_rh|1 2", "hyperx varibad|0"],
                          capture_output=True, text=True, env={**env, "DRY_RUN": "1"}, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    calls = [line.split() for line in proc.stdout.splitlines() if "evaluation/run.py" in line]
    assert len(calls) == 2
    for args, names, seeds, out in (
        (calls[0], ["oracle_rh"], ["1", "2"], "runs/rooms_sparse/oracle_rh_s12"),
        (calls[1], ["hyperx", "varibad"], ["0"], "runs/rooms_sparse/hyperx+varibad_s0"),
    ):
        assert args[args.index("--agents") + 1 : args.index("--tasks")] == names
        assert args[args.index("--seeds") + 1 : args.index("--frames")] == seeds
        assert args[args.index("--frames") + 1] == "5e7" and args[args.index("--eval-every") + 1] == "1000000"
        assert args[args.index("--out") + 1] == out
    bad = subprocess.run([*lane, "oracle_rh"], capture_output=True, text=True, env=env, timeout=60)
    assert bad.returncode == 2 and "AGENTS|SEEDS" in bad.stderr and "evaluation/run.py" not in bad.stdout
    # A part that fails (an unknown agent: evaluation/run.py exits 2) is logged with its exit status.
    failed = subprocess.run([*lane, "no_such_agent|0"], capture_output=True, text=True, env=env, timeout=300)
    assert "end rooms_sparse runs/rooms_sparse/no_such_agent_s0 rc=2" in failed.stdout, failed.stderr[-2000:]


def test_the_catalogue_script_trains_and_deploys_both_ways(tmp_path, tiny_config):
    """A tiny run of scripts/reproduce_catalogue.sh: each record holds the deterministic and the sampled
    deployment on the held-out tasks (--eval-tasks 20: all 48 of Rooms' finite prior, each once)."""
    out = tmp_path / "rooms"
    env = {**os.environ, "AGENTS": "oracle", "SEEDS": "0", "CONFIG": str(tiny_config), "EVAL_EVERY": "200"}
    proc = subprocess.run(["bash", str(ROOT / "scripts" / "reproduce_catalogue.sh"), "rooms_sparse", "400", out],
                          capture_output=True, text=True, env=env, timeout=600)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    record = json.loads((out / "cells" / "oracle__rooms_sparse__s0" / "record.json").read_text())
    assert record["complete"] and [p["frames"] for p in record["curve"]] == [200, 400]
    assert len(record["final"]["online_return_per_task"]) == 48
    assert "online_return" in record["final"]["stochastic"]
    assert "goals_reached" in record["final"]


def _png_size(path: Path) -> tuple[int, int]:
    header = path.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(header[16:20], "big"), int.from_bytes(header[20:24], "big")


def test_the_coverage_panel_is_drawn_only_for_a_task_that_measures_coverage(tmp_path):
    """cheetah_dir_sparse declares a hyper-state grid, so its curves sit beside coverage; point_treasure_sparse
    declares none, so its figure is the curves alone rather than an empty second panel."""
    from hyperstate.evaluation.cell import load_records
    from hyperstate.evaluation.report import write_figures

    results = ROOT / "docs" / "results"
    for source, task in (
        (results / "fig2_turnaround", "cheetah_dir_sparse"),
        (results / "calibration" / "point_treasure_sparse", "point_treasure_sparse"),
    ):
        records = load_records(source)
        assert records and all(r["curve"] for r in records)
        covered = all("coverage" in p for r in records for p in r["curve"])
        out = tmp_path / task
        written = write_figures(out, records)
        curves = out / "figures" / f"curves_{task}.png"
        assert curves in written
        width, height = _png_size(curves)
        assert height == 400
        assert width == (1300 if covered else 800)  # the legend beside the curves
        assert covered == (task == "cheetah_dir_sparse")


def test_catalogue_log_rows_read_curve_wall_and_task_metrics_from_records(tmp_path):
    """research/catalogue/log_rows.py: the log's row of a cell is its curve (last point bold), the last
    point's wall time and the final deployment's declared metrics; an unfinished cell says so."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("log_rows", ROOT / "research" / "catalogue" / "log_rows.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    for name, complete in (("a__t__s0", True), ("b__t__s1", False)):
        cell = tmp_path / "cells" / name
        cell.mkdir(parents=True)
        curve = [{"frames": 1_000_000 * (i + 1), "online_return": r, "wall_seconds": 60.0 * (i + 1)}
                 for i, r in enumerate((-5.0, 12.25))]  # fmt: skip
        final = {"exploration_metric_names": ["goal_reached"], "goal_reached": 0.5, "online_return": 12.25}
        record = {"agent": name[0], "task": "t", "seed": int(name[-1]), "curve": curve, "final": final,
                  "complete": complete}  # fmt: skip
        (cell / "record.json").write_text(json.dumps(record))
    lines = module.markdown(module.cell_rows(tmp_path)).splitlines()
    assert lines[2] == "| a | 0 | 120 s | -5.0, **12.2** | `goal_reached` 0.5 |"
    assert lines[3] == "| b | 1 | 120 s (unfinished, 2,000,000 frames) | -5.0, **12.2** | `goal_reached` 0.5 |"
    with_task = module.markdown(module.cell_rows(tmp_path), task=True).splitlines()
    assert with_task[:2] == ["| task | agent | seed | wall | curve | final |", "|---|---|---|---|---|---|"]
    assert with_task[2] == "| t " + lines[2]
    with pytest.raises(SystemExit, match="no cells"):
        module.cell_rows(tmp_path / "cells")


def test_cpu_identification_reads_the_first_processors_block():
    cpuinfo = (
        "processor\t: 0\nvendor_id\t: AuthenticAMD\ncpu family\t: 25\nmodel\t\t: 17\n"
        "model name\t: AMD EPYC\nstepping\t: 1\n\nprocessor\t: 1\ncpu family\t: 23\nmodel\t\t: 49\n"
    )
    assert provenance.cpu_identification(cpuinfo) == "family 25, model 17, stepping 1"
    assert provenance.cpu_identification("processor\t: 0\nmodel\t\t: 85\n") == "model 85"
    assert provenance.cpu_identification("Processor\t: ARMv8\n") is None
