"""The throughput benchmarks run and write what they promise (numbers are never asserted, only checked)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


# The user's benchmarks (bench/) and the research campaign's probes (research/), tested alike.
SCRIPT_FOLDERS = (ROOT / "bench", ROOT / "research" / "turnaround", ROOT / "research" / "performance")


def script_path(name: str) -> Path:
    (path,) = [folder / name for folder in SCRIPT_FOLDERS if (folder / name).exists()]
    return path


def bench(script: str, *args, out: Path) -> dict:
    env = {**os.environ, "MUJOCO_GL": "disable"}
    subprocess.run(
        [sys.executable, str(script_path(script)), *map(str, args), "--out", str(out)],
        check=True, capture_output=True, text=True, env=env, cwd=ROOT, timeout=600,
    )  # fmt: skip
    return json.loads(out.read_text())


def test_step_path_probe_finds_the_function_and_module_paths_identical(tmp_path):
    result = bench("step_path_probe.py", "--rounds", 2, "--num-envs", 4, out=tmp_path / "step.json")
    assert result["identical_rollouts"] is True  # whole rollouts, bit for bit
    assert set(result["collect_frames_per_second"]) == {"functions", "modules"}
    assert all(v > 0 for v in result["collect_frames_per_second"].values())
    assert result["frames_per_rollout"] == 4 * 200


def test_suite_speed_compares_each_task_with_raw_mujoco_of_its_model(tmp_path):
    tasks = ["mountain_treasure_k8_sparse", "quadruped_goal_sparse"]
    result = bench(
        "suite_speed.py", "--tasks", *tasks, "--steps", 96, "--num-envs", 2, "--threads", 1, out=tmp_path / "s.json"
    )
    assert list(result["tasks"]) == tasks and result["num_envs"] == 2 and result["threads"] == 1
    mountain, quadruped = (result["tasks"][t] for t in tasks)
    # The substeps are the dm_control environments' own: 1 for the kinematic walker, 0.02 s / 0.005 s.
    assert mountain["substeps_per_control_step"] == 1 and quadruped["substeps_per_control_step"] == 4
    for row in (mountain, quadruped):
        assert row["fast_batch"] is True and min(row["raw_mujoco_batch"], row["suite_batch"]) > 0
        assert row["ratio"] == pytest.approx(row["suite_batch"] / row["raw_mujoco_batch"], rel=0.02)


def test_throughput_reports_phases_and_loop_physics(tmp_path):
    result = bench("throughput.py", "--preset", "oracle", "--num-envs", 4, "--frames", 1600, out=tmp_path / "tp.json")
    assert result["frames"] == 1600
    phases = result["share_per_phase"]
    assert {"physics", "inference", "ppo"} <= set(phases)
    assert abs(sum(phases.values()) + result["share_unaccounted"] - 1) < 0.01
    # The JSON rounds seconds to 0.01 s: the rate must lie within what that rounding allows.
    physics_seconds = result["seconds_per_phase"]["physics"]
    low, high = 1600 / (physics_seconds + 0.005), 1600 / max(physics_seconds - 0.005, 1e-3)
    assert low - 1 <= result["loop_physics_frames_per_second"] <= high + 1


def test_physics_state_probe_covers_its_regimes(tmp_path):
    result = bench("physics_state_probe.py", "--episodes", 1, out=tmp_path / "physics.json")
    assert set(result["control_frames_per_second_median"]) == {
        "default_pose_uniform_actions",
        "settled_pose_uniform_actions",
        "settled_pose_bang_bang_actions",
        "settled_pose_periodic_gait",
    }
    assert result["settling_over_episode_steps_median"] > 0


def test_turnaround_summary_measures_first_exits_and_the_way_back():
    summary = _load_bench("turnaround_summary")
    t = np.arange(201, dtype=float)
    # Deployment 0, a forward task: out backwards to −7 m at step 40, then forward to +3 m at step 200.
    wrong_first = np.where(t <= 40, -7 * t / 40, -7 + 10 * (t - 40) / 160)
    # Deployment 1, a forward task: straight out forwards. Deployment 2, a backward task: never leaves.
    right_first, stays = 0.3 * t, np.zeros_like(t)
    x = np.stack([wrong_first, right_first, stays], axis=1)
    directions = np.array([1.0, 1.0, -1.0])
    rewards = np.zeros_like(x)
    wrong_first = summary.suite.exploration_metrics("cheetah_dir_sparse")(
        {"x_displacement": x[..., None]}, rewards, directions[:, None]
    )["wrong_first_exit"]
    forward_first, way_back = summary.exits_and_way_back(x, directions, wrong_first)
    assert forward_first == 0.5  # of the two deployments that left the zone
    assert way_back == pytest.approx(10 / (160 * summary.CONTROL_TIMESTEP))  # 10 m in 160 steps of 0.05 s


def test_turnaround_summary_knows_a_cheetah_on_its_back():
    summary = _load_bench("turnaround_summary")
    pitch = np.array([0.0, 1.0, np.pi, -3.0, 2 * np.pi + 0.1, 2 * np.pi + np.pi])
    assert summary.upside_down(pitch).tolist() == [False, False, True, True, False, True]
    from hyperstate import suite

    env = suite.load("cheetah_dir_sparse", seed=0)
    step = env.reset()
    # the position observation is qpos without x: (rootz, rooty, six joints)
    assert step.observation["position"].shape == (8,)
    assert step.observation["position"][summary.ROOT_PITCH] == env.physics.named.data.qpos["rooty"][0]


def test_turnaround_summary_plots_every_run(tmp_path):
    summary = _load_bench("turnaround_summary")
    rows = [
        {"agent": agent, "seed": seed, "online_return": 100.0 * seed, "curve": [0.0, 50.0 * seed],
         "curve_frames": [1_000_000, 2_000_000]}
        for agent in ("oracle_rh", "hyperx") for seed in (0, 1)
    ]  # fmt: skip
    summary.plot_curves(rows, tmp_path / "curves.png")
    swapped = summary.rename_agents(rows, ["oracle_rh=hyperx", "hyperx=oracle_rh"])
    assert [r["agent"] for r in swapped] == ["hyperx", "hyperx", "oracle_rh", "oracle_rh"]
    assert (tmp_path / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _load_bench(name: str):
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, script_path(f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_learning_speed_compares_settings_at_equal_training_time():
    speed = _load_bench("learning_speed")
    # (frames, training seconds, online return): setting 16 takes 10 s for the budget, setting 64 only 5 s.
    curves = {
        16: [[(100, 2.0, 0.0), (200, 6.0, 40.0), (300, 10.0, 100.0)]],
        64: [[(100, 1.0, 10.0), (200, 3.0, 30.0), (300, 5.0, 60.0)]],
    }
    summary = speed.summarise(curves)
    assert summary["equal_time_seconds"] == 5.0
    assert summary["half_best_final"] == 50.0
    at16, at64 = summary["by_num_envs"]["16"], summary["by_num_envs"]["64"]
    assert at16["online_return_at_equal_time"] == pytest.approx(30.0)  # between (2 s, 0) and (6 s, 40)
    assert at64["online_return_at_equal_time"] == pytest.approx(60.0)
    assert at16["seconds_to_half_best_final"] == 10.0 and at64["seconds_to_half_best_final"] == 5.0
    assert at16["train_frames_per_second"] == pytest.approx(30.0) and at64["final_online_return"] == 60.0
    assert speed.seconds_to_reach(curves[64][0], 61.0) is None


def test_learning_speed_runs_end_to_end(tmp_path):
    result = bench(
        "learning_speed.py", "--preset", "oracle", "--num-envs", 1, 2, "--frames", 800, "--eval-every", 400,
        "--eval-tasks", 2, "--seeds", 0, out=tmp_path / "speed.json",
    )  # fmt: skip
    assert set(result["by_num_envs"]) == {"1", "2"}
    for runs in result["curves"].values():
        frames = [p[0] for p in runs[0]]
        seconds = [p[1] for p in runs[0]]
        assert frames == sorted(frames) and frames[-1] == 800 and frames[0] >= 400
        assert all(b > a for a, b in zip(seconds, seconds[1:], strict=False)) and seconds[0] > 0


def test_snapshot_turns_deploys_each_kept_agent(tmp_path):
    from hyperstate import agents

    agent = agents.make("oracle", **{"ppo.num_envs": 2})
    agent.train("cheetah_dir_sparse", frames=400, progress=False)
    (tmp_path / "snapshots").mkdir()
    for frames in (400_000, 800_000):  # the harness names snapshots by frames
        agent.save(tmp_path / "snapshots" / f"agent_{frames:09d}.pt")
    env = {**os.environ, "MUJOCO_GL": "disable"}
    proc = subprocess.run(
        [sys.executable, str(script_path("snapshot_turns.py")), str(tmp_path), "--every", "1",
         "--json", str(tmp_path / "turns.json")],
        check=True, capture_output=True, text=True, env=env, cwd=ROOT, timeout=600,
    )  # fmt: skip
    lines = [line for line in proc.stdout.splitlines() if "online return" in line]
    assert [line.split()[0] for line in lines] == ["0.4M", "0.8M"]
    assert all("turned" in line and "correct direction" in line for line in lines)
    # The JSON holds each snapshot's own deployment: the same numbers as a deployment made here.
    from hyperstate.evaluation.deploy import deploy, evaluation_tasks, exploration_metric_means

    records = json.loads((tmp_path / "turns.json").read_text())["snapshots"]
    assert [r["frames"] for r in records] == [400_000, 800_000]
    for record, line in zip(records, lines, strict=True):
        deployment = deploy(agents.Agent.load(tmp_path / "snapshots" / f"agent_{record['frames']:09d}.pt"),
                            "cheetah_dir_sparse", evaluation_tasks("cheetah_dir_sparse", 20))  # fmt: skip
        assert record["online_return"] == pytest.approx(deployment.rewards.sum(0).mean(), rel=1e-9, abs=1e-9)
        assert int(line.split()[3]) == round(record["online_return"])
        means = exploration_metric_means("cheetah_dir_sparse", deployment.observations, deployment.rewards,
                                         deployment.tasks)  # fmt: skip
        assert set(means) <= set(record) and {"return_forward", "return_backward", "turned_around"} <= set(record)
        assert record["correct_direction"] == pytest.approx(means["correct_direction"])


def test_gait_probe_tells_the_agent_the_truth_and_measures_each_direction():
    from types import SimpleNamespace

    probe = _load_bench("gait_probe")
    tasks = np.array([[1.0], [-1.0], [-1.0]])  # forward, backward, backward
    seen = []

    class Recorder:
        def act(self, obs, state=None, deterministic=True, reward=None):
            seen.append(obs["belief"].copy())
            return np.zeros((3, 6)), state

    told = probe.Told(Recorder(), tasks)
    told.act({"belief": np.full((3, 2), 0.5, np.float32), "x_displacement": np.zeros((3, 1))})
    # [P(backward), P(forward)], one-hot on the true direction, in the observation's dtype.
    np.testing.assert_array_equal(seen[0], [[0.0, 1.0], [1.0, 0.0], [1.0, 0.0]])
    assert seen[0].dtype == np.float32
    # 200 steps of 0.05 s: forward task to +40 m, backward tasks to -10 m and +2 m.
    steps = np.arange(1, 201)[:, None]
    x = steps / 200 * np.array([[40.0, -10.0, 2.0]])
    rewards = np.tile([[1.0, 0.5, -0.5]], (200, 1))
    result = probe.per_direction(
        SimpleNamespace(observations={"x_displacement": x[..., None]}, tasks=tasks, rewards=rewards)
    )
    assert result["forward"] == pytest.approx({"online_return": 200.0, "final_x": 40.0, "speed": 4.0})
    assert result["backward"] == pytest.approx({"online_return": 0.0, "final_x": -4.0, "speed": 0.4})


def test_gait_probe_tells_a_learned_belief_its_revealed_posterior():
    from types import SimpleNamespace

    import torch

    probe = _load_bench("gait_probe")
    # Four deployments (forward, backward, forward, backward) with 3 belief features; the second forward one
    # never leaves the zone, so only the first forward one's final features reveal the forward posterior.
    x = np.zeros((3, 4, 1))
    x[:, 0, 0], x[:, 1, 0], x[:, 2, 0], x[:, 3, 0] = [1, 6, 9], [-2, -5, -4], [1, 2, 3], [0, -7, -8]
    features = np.zeros((3, 4, 3))
    features[-1] = [[1.0, 2.0, 3.0], [-1.0, 0.0, 1.0], [50.0, 50.0, 50.0], [-3.0, 0.0, 3.0]]
    tasks = np.array([[1.0], [-1.0], [1.0], [-1.0]])
    deployment = SimpleNamespace(observations={"x_displacement": x}, features=features, tasks=tasks)
    revealed = probe.revealed_posteriors(deployment)
    np.testing.assert_allclose(revealed[1.0], [1.0, 2.0, 3.0])
    np.testing.assert_allclose(revealed[-1.0], [-2.0, 0.0, 2.0])  # both backward deployments left the zone
    stayed = SimpleNamespace(observations={"x_displacement": x[:, 2:3]}, features=features[:, 2:3], tasks=tasks[2:3])
    assert probe.revealed_posteriors(stayed) == {}  # nothing left the zone: nothing to tell

    seen = []

    class Belief:
        def features(self, state):
            return torch.zeros(2, 3)

    class Recorder:
        belief = Belief()

        def act(self, obs, state=None, deterministic=True, reward=None):
            seen.append(self.belief.features(state).clone())
            return np.zeros((2, 6)), state

    agent = Recorder()
    told = probe.ToldPosterior(agent, np.array([[-1.0], [1.0]]), revealed)
    told.act({})
    torch.testing.assert_close(seen[0], torch.tensor([[-2.0, 0.0, 2.0], [1.0, 2.0, 3.0]]))
    assert torch.equal(agent.belief.features(None), torch.zeros(2, 3))  # the agent's own method is back
    result = probe.per_direction(
        SimpleNamespace(observations={"x_displacement": x[:, 1:2]}, tasks=tasks[1:2], rewards=np.ones((3, 1)))
    )
    assert result["forward"] == {"online_return": None, "final_x": None, "speed": None}


def test_gait_probe_runs_on_a_varibad_agent(tmp_path):
    from hyperstate import agents

    agent = agents.make("varibad", **{"ppo.num_envs": 2})
    agent.train("cheetah_dir_sparse", frames=400, progress=False)
    agent.save(tmp_path / "agent.pt")
    env = {**os.environ, "MUJOCO_GL": "disable"}
    proc = subprocess.run(
        [sys.executable, str(script_path("gait_probe.py")), str(tmp_path / "agent.pt"), "--json",
         str(tmp_path / "gait.json")],
        capture_output=True, text=True, env=env, cwd=ROOT, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    rows = json.loads((tmp_path / "gait.json").read_text())
    assert rows[0]["deployment"] == "as trained" and rows[0]["forward"]["online_return"] is not None
    # An untrained policy leaves the zone on no task: there is no revealed posterior, so no told row.
    assert [r["deployment"] for r in rows] in (["as trained"], ["as trained", "told: revealed posterior"])


def test_gait_probe_follows_every_nth_snapshot_then_the_final_agent(tmp_path):
    probe = _load_bench("gait_probe")
    cell = tmp_path / "fig2_20m" / "cells" / "oracle_rh__cheetah_dir_sparse__s0"
    (cell / "snapshots").mkdir(parents=True)
    for frames in (998400, 1996800, 2995200, 3993600):
        (cell / "snapshots" / f"agent_{frames:09d}.pt").touch()
    (cell / "record.json").write_text(json.dumps({"frames": 4000000}))
    assert probe.probes(cell, 2) == [
        (1996800, cell / "snapshots" / "agent_001996800.pt"),
        (3993600, cell / "snapshots" / "agent_003993600.pt"),
        (4000000, cell / "agent.pt"),
    ]
    assert probe.probes(cell, 0) == [(4000000, cell / "agent.pt")]
    (cell / "snapshots" / "agent_004000000.pt").touch()  # a snapshot of the final agent is probed once
    assert probe.probes(cell, 1)[-2:] == [
        (3993600, cell / "snapshots" / "agent_003993600.pt"),
        (4000000, cell / "agent.pt"),
    ]
    assert probe.probes(cell / "agent.pt", 3) == [(None, cell / "agent.pt")]
    assert probe.run_name(cell) == "fig2_20m: oracle_rh s0"
    assert probe.run_name(cell / "snapshots" / "agent_001996800.pt") == "fig2_20m: oracle_rh s0"


def test_bonus_x_probe_moves_only_x_and_divides_by_the_deployed_median(tmp_path):
    from hyperstate import agents
    from hyperstate.evaluation.deploy import deploy, evaluation_tasks

    probe = _load_bench("bonus_x_probe")
    agent = agents.make("oracle_rh", **{"ppo.num_envs": 2})
    agent.train("cheetah_dir_sparse", frames=400, progress=False)
    agent.save(tmp_path / "agent.pt")
    tasks = evaluation_tasks("cheetah_dir_sparse", 20)
    row = probe.probe(str(tmp_path / "agent.pt"), tasks)
    # Recomputed here: the saved agent's deployment, its bonus at the deployed hyper-states and with x at +10.
    loaded = agents.Agent.load(tmp_path / "agent.pt")
    d = deploy(loaded, "cheetah_dir_sparse", tasks)
    flat = {k: v.reshape(-1, *v.shape[2:]) for k, v in d.observations.items()}
    features = d.features.reshape(len(flat["x_displacement"]), -1)
    deployed = loaded.bonus_values(flat, features)["0_rnd_hyperstate"]
    moved = loaded.bonus_values({**flat, "x_displacement": np.full_like(flat["x_displacement"], 10.0)}, features)
    assert row["bonus"] == "0_rnd_hyperstate"
    assert row["median_bonus_deployed"] == pytest.approx(np.median(deployed), rel=1e-6)
    assert row["at_x"]["+10"] == pytest.approx(np.median(moved["0_rnd_hyperstate"]) / np.median(deployed), rel=1e-6)
    assert list(row["at_x"]) == ["-20", "-10", "-5", "+0", "+5", "+10", "+20"]
    assert list(row["deployed_over_time"]) == ["0", "10", "50", "199"]
    x = d.observations["x_displacement"][..., 0]
    assert row["deployed_x_range"] == pytest.approx([x.min(), x.max()])


def test_init_probe_sees_the_reference_networks_first_policy_act_and_this_projects_not():
    probe = _load_bench("init_probe")
    from hyperstate.evaluation.deploy import evaluation_tasks

    tasks = evaluation_tasks("cheetah_dir_sparse", 4)
    cleanrl = probe.probe("oracle_rh_icml", 0, {}, tasks)
    reference = probe.probe("oracle_rh_icml", 0, {"ppo.network": "reference"}, tasks)
    # Mean head x0.01: near-zero actions, the cheetah stays where it starts; the reference's acts at full scale.
    assert cleanrl["mean_abs_action"] < 0.02 and cleanrl["deterministic"]["final_abs_x"] < 0.5
    assert reference["mean_abs_action"] > 0.1 and reference["belief_action_difference"] > 0.02
    for row in (cleanrl, reference):
        assert set(row) == {"seed", "deterministic", "sampled", "mean_abs_action", "belief_action_difference"}
        assert all(0.0 <= row[k]["left_zone"] <= 1.0 for k in ("deterministic", "sampled"))


def test_task_pictures_draw_every_sparse_task_with_its_own_rewards(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("task_pictures", ROOT / "scripts" / "task_pictures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    written = module.main(["--out", str(tmp_path)])
    assert sorted(p.name for p in written) == sorted(
        f"task_{n}.png"
        for n in (
            "point_treasure_sparse",
            "point_robot_sparse",
            "cheetah_vel_sparse",
            "quadruped_goal_sparse",
            "mountain_treasure_sparse",
            "rooms_sparse",
        )
    )
    assert all(p.read_bytes()[:4] == b"\x89PNG" for p in written)
    # The treasure explorer is rewarded in episode 1 and goes straight back in episode 2: its second
    # episode earns more than its first, as the task's multi-episode structure promises.
    paths, candidates, rewards, goal = module.explore("point_treasure_sparse")
    half = len(rewards) // 2
    assert len(paths) == 2 and sum(rewards[half:]) > sum(rewards[:half]) > 0
    assert np.min(np.linalg.norm(candidates - goal, axis=1)) < 1e-6  # the goal is one of the candidates


def test_scripted_bracket_ranks_the_mountain_strategies(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("scripted_bracket", ROOT / "scripts" / "scripted_bracket.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    result = module.mountain(angles=8)
    climber, walker = result["MountainClimber"], result["CircleWalker"]
    assert climber["treasures"] == walker["treasures"] == 8
    assert climber["min"] <= climber["mean"] <= climber["max"] and climber["mean"] > walker["mean"]
    # The 8 angles are mountain_treasure_k8_sparse's whole prior, so this is that task's bracket too.
    from hyperstate import suite

    support = suite.task_prior("mountain_treasure_k8_sparse").support()
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    np.testing.assert_allclose(support, np.stack([np.cos(angles), np.sin(angles)], 1), atol=1e-12)


def test_scripted_bracket_ranks_the_point_strategies():
    """The point tasks' bracket: the candidate explorer beats one kept guess and is bounded by the goal
    seeker; after the episode that found the goal, it earns what the seeker earns (it goes straight back)."""
    import importlib.util

    from hyperstate import suite
    from hyperstate.suite import point_robot, scripted

    spec = importlib.util.spec_from_file_location("scripted_bracket", ROOT / "scripts" / "scripted_bracket.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    result = module.point_tasks(angles=8)
    treasure, robot = result["point_treasure_sparse"], result["point_robot_sparse"]
    assert treasure["PointGoalSeeker"]["mean"] > treasure["PointExplorer"]["mean"] > treasure["one_guess"]["mean"] > 0
    assert treasure["one_guess"]["min"] == 0  # a kept guess earns nothing on the other three goals
    assert robot["PointGoalSeeker"]["mean"] > robot["ArcSweeper"]["mean"] > 0 and robot["ArcSweeper"]["min"] > 0
    candidates = point_robot.HalfCircleGoalPrior(num_goals=4).support()
    for goal in candidates:
        runs = {}
        for name, strategy in (
            ("explorer", scripted.PointExplorer(candidates)),
            ("seeker", scripted.PointGoalSeeker()),
        ):
            env = suite.load("point_treasure_sparse", seed=0, goal=goal, privileged=True)
            rewards, obs = scripted.rollout(env, strategy)
            # Recomputed from where the steps ended (the episode's last step shows the next start: left out).
            paid = np.linalg.norm(obs["position"] - goal, axis=1) <= point_robot.GOAL_RADIUS
            inner = obs["inner_episode"][:, 0]
            same = np.r_[True, inner[1:] == inner[:-1]]
            np.testing.assert_array_equal(rewards[same], paid[same].astype(float))
            runs[name] = rewards[len(rewards) // 2 :].sum()
        assert runs["explorer"] == runs["seeker"] > 30
