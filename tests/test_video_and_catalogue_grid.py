"""evaluation/run.py on the task catalogue: incompatible pairs skipped, task metrics in the summary,
videos rendered (MUJOCO_GL=egl), bonuses on the task's declared position keys."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hyperstate import agents, suite

ROOT = Path(__file__).resolve().parents[1]
TINY = {"ppo.num_envs": 4, "ppo.rollout_length": 50, "vae.batch_trajectories": 2, "vae.subsample_elbos": 10}


def run_grid(tmp_path: Path, args: str, out: Path) -> subprocess.CompletedProcess:
    """evaluation/run.py on one seed, 400 frames, 2 held-out tasks, with the tiny config."""
    config = tmp_path / "tiny.toml"
    config.write_text("[all]\n" + "".join(f'"{k}" = {v}\n' for k, v in TINY.items()))
    common = f"--seeds 0 --frames 400 --eval-tasks 2 --no-reference --workers 1 --no-progress --config {config}"
    env = {**os.environ, "MUJOCO_GL": "disable"}  # training without rendering; --video switches to egl
    command = [sys.executable, str(ROOT / "evaluation" / "run.py"), *common.split(), *args.split(), "--out", str(out)]
    return subprocess.run(command, capture_output=True, text=True, env=env, timeout=600)


def test_grid_skips_incompatible_pairs_and_reports_task_metrics(tmp_path):
    out = tmp_path / "out"
    result = run_grid(tmp_path, "--agents oracle hyperx --tasks point_robot_sparse point_treasure_sparse", out)
    assert result.returncode == 0, result.stderr
    assert "skipping oracle on point_robot_sparse: the oracle belief needs a task with an exact belief" in result.stderr
    cells = sorted(p.name for p in (out / "cells").iterdir())
    assert cells == [
        "hyperx__point_robot_sparse__s0",
        "hyperx__point_treasure_sparse__s0",
        "oracle__point_treasure_sparse__s0",
    ]
    with (out / "summary.csv").open() as f:
        rows = {(r["agent"], r["task"]): r for r in csv.DictReader(f)}
    assert set(rows) == {
        ("hyperx", "point_robot_sparse"),
        ("hyperx", "point_treasure_sparse"),
        ("oracle", "point_treasure_sparse"),
    }
    for row in rows.values():  # the point robot's own metrics reach the summary
        assert 0.0 <= float(row["goal_reached"]) <= 1.0 and 0.0 <= float(row["last_episode_at_goal"]) <= 1.0
    assert not (out / "videos").exists()  # only --video renders
    # Which cells a video is made of by default: the first seed of each (agent, task), task by task.
    from hyperstate.evaluation import video

    grid = json.loads((out / "grid.json").read_text())
    assert video.default_cells({**grid, "seeds": [3, 5]}) == [
        "oracle__point_robot_sparse__s3",
        "hyperx__point_robot_sparse__s3",
        "oracle__point_treasure_sparse__s3",
        "hyperx__point_treasure_sparse__s3",
    ]


def test_video_renders_each_cells_deployments_with_caption_and_goal(tmp_path):
    # One cell: software rendering costs ~50 ms a frame on 2 cores, and every cell's video is the same code.
    out = tmp_path / "out"
    result = run_grid(tmp_path, "--agents oracle --tasks point_treasure_sparse --video --video-tasks 2", out)
    assert result.returncode == 0, result.stderr
    import imageio_ffmpeg

    videos = sorted(p.name for p in (out / "videos").iterdir())
    assert videos == ["oracle__point_treasure_sparse__s0.mp4"]
    reader = imageio_ffmpeg.read_frames(str(out / "videos" / "oracle__point_treasure_sparse__s0.mp4"))
    meta = next(reader)
    frames = np.stack([np.frombuffer(f, np.uint8).reshape(240, 320, 3) for f in reader])
    assert meta["size"] == (320, 240) and meta["fps"] == 20.0
    assert len(frames) == 2 * 101  # two tasks: each the first observation + 2 MDP episodes of 50 steps
    caption, scene = frames[:, :40].astype(float), frames[:, 60:].astype(float)
    assert (caption < 40).mean() > 0.7 and (caption > 200).mean() > 0.02  # white text on black
    # The scene: the light floor with the grey candidate discs and the green goal drawn into it.
    green = (scene[..., 1] > scene[..., 0] + 40) & (scene[..., 1] > scene[..., 2] + 40)
    assert green.any(axis=(1, 2)).all()
    # The second deployment is on the second held-out task: its goal is drawn elsewhere.
    columns = np.arange(scene.shape[2])
    goal_x = [(green[i].sum(0) * columns).sum() / green[i].sum() for i in (0, 101)]
    assert abs(goal_x[0] - goal_x[1]) > 20


def test_bonuses_read_the_position_keys_the_task_declares():
    assert suite.position_keys("cheetah_dir_sparse") == ("x_displacement",)
    assert suite.position_keys("point_robot_sparse") == ("position",)
    agent = agents.make("hyperx", **TINY)
    agent.check_task("point_robot_sparse")  # builds: position is an observation of the point robot
    custom = agents.make("hyperx", **TINY, **{"bonuses.0.state_keys": ["velocity"], "bonuses.1.state_keys": None})
    custom.check_task("point_robot_sparse")
    with pytest.raises(ValueError, match="bonuses.0.state_keys must be a list of observation keys"):
        agents.make("hyperx", **{"bonuses.0.state_keys": "velocity"})

    @suite.register("nameless_positions")
    def nameless(seed=None, **kwargs):
        return suite.load("point_robot_sparse", seed=seed, **kwargs)

    try:
        with pytest.raises(ValueError, match="declares none; set bonuses.0.state_keys to some of"):
            agent.check_task("nameless_positions")
        agents.make("oracle", **TINY).check_task("point_treasure_sparse")
        with pytest.raises(ValueError, match="exact belief"):
            agents.make("oracle", **TINY).check_task("nameless_positions")
    finally:
        suite.unregister("nameless_positions")
