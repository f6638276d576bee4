"""The command line as a new user meets it: budgets as written in papers, one-line refusals, extending a
finished run, and the installed console scripts."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
import torch
from test_evaluation import TINY_CONFIG, run

from hyperstate.agents import serialization
from hyperstate.evaluation.run import frame_count

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def tiny(tmp_path) -> Path:
    (path := tmp_path / "tiny.toml").write_text(TINY_CONFIG)
    return path


@pytest.mark.parametrize(
    "text,frames",
    [("20000000", 20_000_000), ("2e7", 20_000_000), ("20M", 20_000_000), ("1.5M", 1_500_000), ("500k", 500_000),
     ("20_000_000", 20_000_000), ("4E8", 400_000_000), ("1g", 10**9)],
)  # fmt: skip
def test_budgets_as_papers_write_them(text, frames):
    assert frame_count(text) == frames


@pytest.mark.parametrize("text", ["2.5", "1e-3", "20X", "abc", "", "1.00001k"])
def test_budgets_that_are_not_whole_numbers_are_refused(text):
    with pytest.raises(argparse.ArgumentTypeError):
        frame_count(text)


@pytest.mark.parametrize(
    "args,message",
    [
        (["--frames", "2.5"], "'2.5' is not a whole number of frames"),
        (["--tasks", "cheetah_dir_sparce"], "unknown task 'cheetah_dir_sparce' (did you mean cheetah_dir_sparse"),
        (["--physics-threads", "0"], "--physics-threads must be positive"),
    ],
)
def test_bad_command_lines_are_refused_in_one_line(tmp_path, args, message):
    base = {"--agents": "oracle", "--tasks": "cheetah_dir", "--frames": "100", "--out": str(tmp_path / "o")}
    for flag, value in zip(args[::2], args[1::2], strict=True):
        base[flag] = value
    proc = run([x for pair in base.items() for x in pair])
    assert proc.returncode == 2
    assert message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "override,message", [('"ppo.lr" = -1.0', "ppo.lr must be positive"), ('"ppo.num_envs" = 0', "ppo.num_envs")]
)
def test_out_of_range_settings_are_refused_before_anything_runs(tmp_path, override, message):
    config = tmp_path / "bad.toml"
    config.write_text(f"[all]\n{override}\n")
    proc = run(["--agents", "oracle", "--tasks", "cheetah_dir", "--frames", 100, "--config", config,
                "--out", tmp_path / "o"])  # fmt: skip
    assert proc.returncode == 2 and message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_a_budget_beyond_the_learning_rate_horizon_is_refused(tmp_path):
    proc = run(["--agents", "oracle", "--tasks", "cheetah_dir", "--frames", "6e7", "--out", tmp_path / "o"])
    assert proc.returncode == 2 and "outlasts ppo.lr_anneal_frames" in proc.stderr


def _grid(tiny, out, frames, agent="oracle", *extra):
    return run(["--agents", agent, "--tasks", "cheetah_dir_sparse", "--seeds", "0", "--frames", frames,
                "--eval-every", 200, "--eval-tasks", 2, "--config", tiny, "--no-reference", "--no-progress",
                "--no-diagnostics", "--out", out, *extra])  # fmt: skip


def _without_times(record: dict) -> dict:
    record = json.loads(json.dumps(record))
    record.pop("versions")
    for point in record["curve"]:
        point.pop("wall_seconds")
    return record


def _leaves(tree, path="") -> dict:
    """{path: bytes} of every tensor and array in a nested state."""
    if isinstance(tree, dict):
        return {k: v for key, sub in tree.items() for k, v in _leaves(sub, f"{path}/{key}").items()}
    if isinstance(tree, (list, tuple)):
        return {k: v for i, sub in enumerate(tree) for k, v in _leaves(sub, f"{path}/{i}").items()}
    if isinstance(tree, torch.Tensor):
        return {path: tree.detach().numpy().tobytes()}
    if isinstance(tree, np.ndarray):
        return {path: tree.tobytes()}
    return {}


def test_resume_with_a_larger_budget_equals_a_run_started_with_it(tmp_path, tiny):
    cell = "cells/oracle_rh__cheetah_dir_sparse__s0"
    assert _grid(tiny, tmp_path / "long", 800, "oracle_rh").returncode == 0
    assert _grid(tiny, tmp_path / "short", 400, "oracle_rh").returncode == 0
    extended = _grid(tiny, tmp_path / "short", 800, "oracle_rh", "--resume")
    assert extended.returncode == 0, extended.stderr
    long = json.loads((tmp_path / "long" / cell / "record.json").read_text())
    grown = json.loads((tmp_path / "short" / cell / "record.json").read_text())
    assert (
        grown["complete"] and grown["frames"] == 800 and [p["frames"] for p in grown["curve"]] == [200, 400, 600, 800]
    )
    assert _without_times(grown) == _without_times(long)
    a = serialization.load(tmp_path / "long" / cell / "agent.pt", kind="agent")["modules"]
    b = serialization.load(tmp_path / "short" / cell / "agent.pt", kind="agent")["modules"]
    assert _leaves(a) and _leaves(a) == _leaves(b)  # every parameter and normaliser statistic, bit for bit
    assert json.loads((tmp_path / "short" / "grid.json").read_text())["frames"] == 800


def test_extending_a_run_whose_schedule_follows_its_budget_is_refused(tmp_path, tiny):
    assert _grid(tiny, tmp_path / "o", 400, "oracle_paper").returncode == 0
    proc = _grid(tiny, tmp_path / "o", 800, "oracle_paper", "--resume")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert "cannot extend oracle_paper to 800 frames: ppo.lr_anneal_frames is null" in proc.stderr


def test_a_damaged_record_is_named_with_what_to_do(tmp_path, tiny):
    assert _grid(tiny, tmp_path / "o", 200).returncode == 0
    record = tmp_path / "o" / "cells" / "oracle__cheetah_dir_sparse__s0" / "record.json"
    record.write_text(record.read_text()[:100])  # a partial copy
    proc = _grid(tiny, tmp_path / "o", 200, "oracle", "--resume")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert str(record) in proc.stderr and "partial copy" in proc.stderr and "JSONDecodeError" in proc.stderr


def test_console_scripts_work_from_a_plain_install_into_a_fresh_venv(tmp_path):
    """`pip install .` as two steps: the wheel built from the checkout, installed without the repository;
    its dependencies are this environment's (a .pth file), so the test downloads nothing."""
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                    str(tmp_path / "wheels"), str(ROOT)], check=True, capture_output=True, timeout=600)  # fmt: skip
    (wheel,) = (tmp_path / "wheels").glob("hyperstate-*.whl")
    venv = tmp_path / "fresh"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=300)
    subprocess.run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "--no-deps",
                    "-q", str(wheel)], check=True, capture_output=True, timeout=600)  # fmt: skip
    purelib = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    fresh_site = subprocess.run([venv / "bin" / "python", "-c", purelib], check=True, capture_output=True,
                                text=True).stdout.strip()  # fmt: skip
    Path(fresh_site, "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {"MUJOCO_GL": "disable"}
    for command, usage in (
        ("hyperstate-run", "--agents"),
        ("hyperstate-merge", "--into"),
        ("hyperstate-report", "--low-agent"),
    ):
        proc = subprocess.run([venv / "bin" / command, "--help"], capture_output=True, text=True, env=env,
                              cwd=tmp_path, timeout=300)  # fmt: skip
        assert proc.returncode == 0 and proc.stdout.startswith(f"usage: {command}") and usage in proc.stdout
    where = subprocess.run([venv / "bin" / "python", "-c", "import hyperstate; print(hyperstate.__file__)"],
                           capture_output=True, text=True, env=env, cwd=tmp_path, check=True).stdout  # fmt: skip
    assert where.startswith(fresh_site)  # the installed package, not the checkout
    proc = subprocess.run([venv / "bin" / "hyperstate-run", "--agents", "orakel", "--tasks", "cheetah_dir",
                           "--frames", "2e7", "--out", tmp_path / "o"], capture_output=True, text=True, env=env,
                          cwd=tmp_path, timeout=300)  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.startswith("hyperstate-run: error: unknown agent 'orakel'")
