"""The task catalogue beyond cheetah-direction: point robot, cheetah velocity, quadruped, mountain, rooms.

Every task gets the same battery as cheetah_dir (dm_env conformance, specs, determinism, batched
simulator equality step for step); each task's reward and belief are recomputed independently.
"""

import unittest

import numpy as np
import pytest
from dm_env import test_utils

from hyperstate import suite
from hyperstate.suite.cheetah_vel import CheetahVelocity, follows_the_target, velocity_metrics
from hyperstate.suite.point_robot import HalfCircleGoalPrior, goal_metrics
from hyperstate.suite.scripted import gait

NEW_TASKS = {
    # name: small kwargs for fast tests (short MDP episodes, two of them so inner resets are exercised)
    "point_robot_sparse": {"episode_length": 20, "episodes_per_task": 2},
    "point_robot": {"episode_length": 20},
    "point_robot_3ep": {"episode_length": 20, "episodes_per_task": 2},
    "point_treasure_sparse": {"episode_length": 20},
    "cheetah_vel_sparse": {"episode_length": 20, "episodes_per_task": 2},
    "cheetah_vel": {"episode_length": 20},
    "quadruped_goal_sparse": {"episode_length": 20, "episodes_per_task": 2},
    "mountain_treasure_sparse": {"episode_length": 20, "episodes_per_task": 2},
    "mountain_treasure_k8_sparse": {"episode_length": 20, "episodes_per_task": 2},
    "mountain_treasure": {"episode_length": 20},
    "rooms_sparse": {"episode_length": 20, "episodes_per_task": 2},
}
BELIEF_TASKS = {"point_treasure_sparse", "mountain_treasure_k8_sparse", "rooms_sparse"}  # finite priors


def action_size(name: str) -> int:
    return {"cheetah": 6, "quadruped": 12}.get(name.split("_")[0], 2)


# dm_env conformance ------------------------------------------------------------------------------
def _conformance_case(name: str, kwargs: dict) -> type:
    class Case(test_utils.EnvironmentTestMixin, unittest.TestCase):
        def make_object_under_test(self):
            return suite.load(name, seed=0, privileged=True, **kwargs)

        def make_action_sequence(self):
            rng = np.random.default_rng(0)
            for _ in range(2 * 20 * kwargs.get("episodes_per_task", 2) + 5):  # past a BAMDP end and reset
                yield rng.uniform(-1, 1, action_size(name))

    Case.__name__ = Case.__qualname__ = f"Conformance_{name}"
    return Case


for _name, _kwargs in NEW_TASKS.items():
    globals()[f"Conformance_{_name}"] = _conformance_case(_name, _kwargs)


@pytest.mark.parametrize("name", sorted(NEW_TASKS))
def test_specs_finite_fresh_arrays_and_registration(name):
    assert name in suite.TASKS
    env = suite.load(name, seed=3, privileged=True, **NEW_TASKS[name])
    spec = env.observation_spec()
    previous = env.reset().observation
    rng = np.random.default_rng(0)
    for _ in range(45):
        step = env.step(rng.uniform(-1, 1, action_size(name)))
        assert isinstance(step.reward, float)
        for k, v in step.observation.items():
            spec[k].validate(v)
            assert np.all(np.isfinite(v)), k
            assert not np.shares_memory(v, previous[k]), k
        previous = step.observation
        if step.last():
            previous = env.reset().observation
    assert "task" in spec and ("belief" in spec) == (name in BELIEF_TASKS)


@pytest.mark.parametrize("name", sorted(NEW_TASKS))
def test_same_seed_same_trajectory_different_seed_different(name):
    def trajectory(seed):
        env = suite.load(name, seed=seed, privileged=True, **NEW_TASKS[name])
        rng = np.random.default_rng(1)
        ts = env.reset()
        out = [np.concatenate([ts.observation["task"], ts.observation["position"]])]
        for _ in range(15):
            ts = env.step(rng.uniform(-1, 1, action_size(name)))
            out.append(np.concatenate([[ts.reward], ts.observation["position"]]))
        # The point robot always starts at the origin: its seed shows in the goals of later resets.
        out += [env.reset().observation["task"] for _ in range(5)]
        return np.concatenate(out)

    np.testing.assert_array_equal(trajectory(4), trajectory(4))
    assert not np.allclose(trajectory(4), trajectory(5))


@pytest.mark.parametrize("name", sorted(NEW_TASKS))
def test_batch_equals_dm_control_step_for_step(name):
    n, seed, kwargs = 3, 11, NEW_TASKS[name]
    vec = suite.batch(name, n, seed=seed, privileged=True, **kwargs)
    envs = [suite.load(name, seed=s, privileged=True, **kwargs) for s in suite.spawn_seeds(seed, n)]
    vec.reset()
    for env in envs:
        env.reset()
    rng = np.random.default_rng(2)
    steps = kwargs["episode_length"] * kwargs.get("episodes_per_task", suite.load(name, seed=0).task.episodes_per_task)
    resets = 0
    for t in range(steps + 7):
        if name.startswith("cheetah"):  # one copy runs out of the zone, one acts randomly, one out of bounds
            action = np.stack([gait(1.0)(t), rng.uniform(-1, 1, 6), rng.uniform(-2, 2, 6)])
        elif name.startswith("quadruped"):
            action = rng.uniform(-1.2, 1.2, (3, 12))
        else:  # one copy heads for the goals' half circle, the others wander
            action = np.stack([[0.3, 1.0], rng.uniform(-1, 1, 2), rng.uniform(-2, 2, 2)])
        out = vec.step(action)
        for i, env in enumerate(envs):
            step = env.step(action[i])
            assert step.reward == out.reward[i]
            assert step.last() == out.last[i]
            for k, v in step.observation.items():
                np.testing.assert_array_equal(out.final_observation[k][i], v, err_msg=k)
            if step.last():
                resets += 1
                step = env.reset()
            for k, v in step.observation.items():
                np.testing.assert_array_equal(out.observation[k][i], v, err_msg=k)
    assert resets == n
    assert vec.observation_spec() == {k: v for k, v in envs[0].observation_spec().items()}


@pytest.mark.parametrize(
    "name", ["point_treasure_sparse", "cheetah_vel_sparse", "mountain_treasure_k8_sparse", "rooms_sparse"]
)
def test_batch_snapshot_restores_exactly(name):
    vec = suite.batch(name, 2, seed=0, privileged=True, episode_length=10)
    vec.reset()
    rng = np.random.default_rng(0)
    for _ in range(13):
        vec.step(rng.uniform(-1, 1, (2, action_size(name))))
    state = vec.state_dict()
    actions = rng.uniform(-1, 1, (12, 2, action_size(name)))
    first = [vec.step(a) for a in actions]
    vec.load_state_dict(state)
    second = [vec.step(a) for a in actions]
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a.reward, b.reward)
        for k in a.observation:
            np.testing.assert_array_equal(a.observation[k], b.observation[k])


# Point robot -------------------------------------------------------------------------------------
def drive_to(env, target, max_steps=60):
    """Proportional controller towards `target`; returns the rewards of the steps taken until it arrives."""
    rewards = []
    for _ in range(max_steps):
        error = np.asarray(target) - env.physics.named.data.qpos[["x", "y"]]
        if np.linalg.norm(error) < 0.05:
            break
        rewards.append(env.step(np.clip(5.0 * error, -1, 1)).reward)
    return rewards


@pytest.mark.parametrize("name", ["point_robot_sparse", "point_robot"])
def test_point_robot_reward_recomputed_from_physics(name):
    env = suite.load(name, seed=7, privileged=True, episodes_per_task=1)  # no physics reset after step 100
    goal = env.reset().observation["task"]
    assert np.linalg.norm(goal) == pytest.approx(1.0) and goal[1] >= 0.0  # on the upper half circle
    rng = np.random.default_rng(0)
    rewarded = 0
    for t in range(100):
        action = np.clip(3.0 * (goal - env.physics.data.qpos[:2]), -1, 1) if t > 40 else rng.uniform(-1, 1, 2)
        step = env.step(action)
        distance = np.hypot(*(env.physics.named.data.qpos[["x", "y"]] - goal))
        expected = float(distance <= 0.2) if name == "point_robot_sparse" else -distance
        assert step.reward == pytest.approx(expected, abs=1e-12)
        rewarded += distance <= 0.2
    assert rewarded > 20  # the controller reached the goal and stayed


def test_point_robot_velocity_follows_the_action_with_a_time_constant():
    """Damping 5, gear 10, mass 1: v(t) = 2 m/s · (1 − exp(−t / 0.2 s)) at full throttle; the arena stops it."""
    env = suite.load("point_robot_sparse", seed=0, goal=[0.0, 1.0])
    env.reset()
    for _ in range(12):  # 0.6 s
        env.step(np.array([1.0, 0.0]))
    assert env.physics.data.qvel[0] == pytest.approx(2.0 * (1 - np.exp(-3.0)), rel=0.02)
    assert env.physics.data.qpos[0] == pytest.approx(2.0 * (0.6 - 0.2 * (1 - np.exp(-3.0))), rel=0.03)
    assert env.physics.data.qpos[1] == 0.0
    for _ in range(40):
        env.step(np.array([1.0, 0.0]))
    assert env.physics.data.qpos[0] == pytest.approx(1.5, abs=0.02)  # pressed against the arena's edge
    # The joint limit is soft: pressed into the corner, the robot stands past the walls but inside the plot.
    x_min, x_max, y_min, y_max = suite.top_down("point_robot_sparse").extent
    for _ in range(40):
        env.step(np.array([1.0, 1.0]))
    x, y = env.physics.data.qpos[:2]
    assert x > 1.5 and y > 1.5 and x < x_max and y < y_max


def test_half_circle_prior_continuous_and_finite():
    rng = np.random.default_rng(0)
    goals = np.array([HalfCircleGoalPrior().sample(rng) for _ in range(4000)])
    angles = np.arctan2(goals[:, 1], goals[:, 0])
    np.testing.assert_allclose(np.linalg.norm(goals, axis=1), 1.0)
    assert angles.min() >= 0 and angles.max() <= np.pi
    assert np.histogram(angles, bins=4, range=(0, np.pi))[0].min() > 900  # uniform in angle
    finite = HalfCircleGoalPrior(num_goals=4)
    support = finite.support()
    np.testing.assert_allclose(support, [[1, 0], [0.5, np.sqrt(3) / 2], [-0.5, np.sqrt(3) / 2], [-1, 0]], atol=1e-12)
    draws = [int(np.argmin(np.linalg.norm(support - finite.sample(rng), axis=1))) for _ in range(4000)]
    assert np.bincount(draws).min() > 900 and HalfCircleGoalPrior().support() is None


def test_treasure_belief_eliminates_visited_candidates_and_is_held_across_episodes():
    env = suite.load("point_treasure_sparse", seed=0, privileged=True, goal=[-0.5, np.sqrt(3) / 2])
    support = env.task.prior.support()
    ts = env.reset()
    np.testing.assert_array_equal(ts.observation["belief"], [0.25] * 4)
    drive_to(env, support[0])  # an empty candidate: ruled out
    np.testing.assert_allclose(env.task.belief, [0, 1 / 3, 1 / 3, 1 / 3])
    drive_to(env, support[1])
    np.testing.assert_allclose(env.task.belief, [0, 0, 0.5, 0.5])
    rewards = drive_to(env, support[2])  # the treasure
    assert rewards[-1] == 1.0
    np.testing.assert_array_equal(env.task.belief, [0, 0, 1, 0])
    while env.task.inner_episode == 0:
        ts = env.step(np.zeros(2))
    np.testing.assert_array_equal(ts.observation["position"], [0, 0])  # the robot is reset ...
    np.testing.assert_array_equal(ts.observation["belief"], [0, 0, 1, 0])  # ... the belief is not


def test_treasure_exploring_in_episode_one_pays_off_in_episode_two():
    """Bayes-adaptive behaviour (visit candidates until rewarded, then go straight back) earns more in
    episode 2 than in episode 1, and more over both than always going to one candidate."""

    def run(goal_index, policy):
        env = suite.load("point_treasure_sparse", seed=0, privileged=True, goal=support[goal_index])
        env.reset()
        per_episode = [0.0, 0.0]
        ts = None
        while ts is None or not ts.last():
            episode = env.task.inner_episode
            target = policy(env.task.belief, episode)
            error = target - env.physics.data.qpos[:2]
            ts = env.step(np.clip(5.0 * error, -1, 1))
            per_episode[episode] += ts.reward
        return per_episode

    support = HalfCircleGoalPrior(num_goals=4).support()
    explore = lambda belief, episode: support[int(np.argmax(belief))]  # noqa: E731  first candidate left
    fixed = lambda belief, episode: support[1]  # noqa: E731
    adaptive = np.array([run(k, explore) for k in range(4)])
    naive = np.array([run(k, fixed) for k in range(4)])
    assert np.all(adaptive[:, 1] > 30)  # episode 2: straight to the treasure, about 40 of 50 steps there
    assert adaptive[:, 1].mean() > adaptive[:, 0].mean() + 10
    assert adaptive.sum(1).mean() > naive.sum(1).mean() + 20


def test_goal_metrics_on_known_trajectories():
    # 2 MDP episodes of 2 steps; deployment 0 reaches its goal in the second episode only, 1 never.
    position = np.array(
        [[[0.5, 0.0], [0.0, 0.0]], [[0.0, 0.0], [0.0, 0.0]], [[0.95, 0.1], [0.0, 0.5]], [[1.0, 0.0], [0.0, 0.5]]]
    )
    inner = np.array([0, 1, 1, 1], float)[:, None, None].repeat(2, 1)
    tasks = np.array([[1.0, 0.0], [-1.0, 0.0]])
    m = goal_metrics({"position": position, "inner_episode": inner}, np.zeros((4, 2)), tasks)
    np.testing.assert_array_equal(m["goal_reached"], [1, 0])
    np.testing.assert_array_equal(m["first_goal_step"], [3, np.nan])
    np.testing.assert_array_equal(m["last_episode_at_goal"], [1.0, 0.0])


def test_point_tasks_success_needs_finding_and_returning_to_the_goal():
    """The scripted candidate explorer succeeds on point_treasure_sparse; one kept guess finds the goal in a
    quarter of the tasks and fails; finding without returning fails too."""
    from hyperstate.suite import scripted

    success = suite.success("point_treasure_sparse")
    assert success is suite.success("point_robot_sparse") and suite.success("point_robot") is None
    support = suite.task_prior("point_treasure_sparse").support()
    for strategy, expected in ((scripted.PointExplorer(support), True), (scripted.PointExplorer(support[:1]), False)):
        per_task = []
        for goal in support:
            env = suite.load("point_treasure_sparse", seed=0, goal=goal)
            _, obs = scripted.rollout(env, strategy)
            per_task.append(goal_metrics({k: v[:, None] for k, v in obs.items()}, np.zeros((100, 1)), goal[None]))
        final = {k: float(np.mean([m[k] for m in per_task])) for k in ("goal_reached", "last_episode_at_goal")}
        assert success(final) is expected, final
    assert not success({"goal_reached": 1.0, "last_episode_at_goal": 0.4})


# Cheetah velocity --------------------------------------------------------------------------------
def test_cheetah_velocity_reward_recomputed_from_physics():
    target = 2.0
    env = suite.load("cheetah_vel_sparse", seed=2, target_velocity=target, privileged=True)
    ts = env.reset()
    assert ts.observation["task"][0] == target
    x_start = float(env.physics.named.data.qpos["rootx"][0])
    run = gait(1.0)
    paid = 0
    for t in range(200):
        action = run(t)
        x_before = float(env.physics.named.data.qpos["rootx"][0])
        step = env.step(action)
        x = float(env.physics.named.data.qpos["rootx"][0])
        velocity = (x - x_before) / 0.05
        outside = abs(x - x_start) >= 5.0
        a = np.clip(action, -1, 1)
        expected = (max(0.0, 1.0 - abs(velocity - target)) if outside else 0.0) - 0.05 * float(a @ a)
        assert step.reward == pytest.approx(expected, abs=1e-12)
        paid += outside and abs(velocity - target) < 1.0
    assert paid > 0  # the scripted gait passes through the target speed somewhere outside the zone


def test_cheetah_velocity_error_recomputed_from_physics():
    target, zone = 1.0, 0.5
    env = suite.load("cheetah_vel_sparse", seed=2, target_velocity=target, zone_radius=zone, privileged=True)
    env.reset()
    x_start = float(env.physics.named.data.qpos["rootx"][0])
    run, xs, velocities, rewards, errors = gait(1.0), [], [], [], []
    for t in range(200):
        x_before = float(env.physics.named.data.qpos["rootx"][0])
        step = env.step(run(t))
        x = float(env.physics.named.data.qpos["rootx"][0])
        xs.append(step.observation["x_displacement"])
        velocities.append(step.observation["velocity"])
        rewards.append(step.reward)
        if abs(x - x_start) >= zone:
            errors.append(abs((x - x_before) / 0.05 - target))
    assert len(errors) > 100
    observations = {"x_displacement": np.array(xs)[:, None], "velocity": np.array(velocities)[:, None]}
    metrics = velocity_metrics(observations, np.array(rewards)[:, None], np.array([[target]]), zone_radius=zone)
    assert metrics["velocity_error"][0] == pytest.approx(np.mean(errors), abs=1e-9)


def test_cheetah_velocity_error_skips_the_reset_and_success_needs_the_target():
    """Two MDP episodes at 2 m/s (0.1 m a step) with v* = 1.5: every measured step errs 0.5 m/s; the jump
    back to the start is not a speed. A deployment that never leaves has no error."""
    steps = np.arange(10)
    x = np.concatenate([0.1 * (steps + 1), 0.1 * (steps + 1)])
    observations = {
        "x_displacement": np.stack([x, np.zeros_like(x)], axis=1)[..., None],
        "velocity": np.zeros((20, 2, 9)),
    }
    metrics = velocity_metrics(observations, np.zeros((20, 2)), np.array([[1.5], [1.5]]), zone_radius=0.35)
    assert metrics["velocity_error"][0] == pytest.approx(0.5, abs=1e-9) and np.isnan(metrics["velocity_error"][1])
    success = suite.success("cheetah_vel_sparse")
    assert success is follows_the_target and suite.success("cheetah_vel") is None
    assert success({"left_zone": 1.0, "velocity_error": 0.5})
    assert not success({"left_zone": 1.0, "velocity_error": 0.76})  # the best single speed on the held-out tasks
    assert not success({"left_zone": 0.85, "velocity_error": 0.1})
    assert not success({"left_zone": 0.0, "velocity_error": None})


def test_cheetah_velocity_prior_and_arguments():
    rng = np.random.default_rng(0)
    task = CheetahVelocity(random=rng)
    draws = np.array([task.prior.sample(rng)[0] for _ in range(4000)])
    assert draws.min() >= 0 and draws.max() <= 3 and draws.mean() == pytest.approx(1.5, abs=0.05)
    assert task.prior.support() is None and task.prior_belief() is None
    narrow = suite.load("cheetah_vel_sparse", seed=0, velocity_range=(1.0, 1.0), privileged=True)
    assert narrow.reset().observation["task"][0] == 1.0
    with pytest.raises(ValueError, match="low <= high"):
        suite.load("cheetah_vel_sparse", velocity_range=(2.0, 1.0))
    with pytest.raises(ValueError, match="target_velocity"):
        suite.load("cheetah_vel_sparse", target_velocity=[1.0, 2.0])
    with pytest.raises(TypeError, match="direction"):
        suite.load("cheetah_vel_sparse", direction=1.0)


def test_point_robot_bad_arguments():
    with pytest.raises(ValueError, match="not one of the prior's 4 goals"):
        suite.load("point_treasure_sparse", goal=[0.0, 1.0])
    with pytest.raises(ValueError, match="goal_radius"):
        suite.load("point_robot_sparse", goal_radius=0.0)
    with pytest.raises(ValueError, match="num_goals"):
        suite.load("point_robot_sparse", num_goals=0)
    env = suite.load("point_robot_sparse", seed=0)
    env.reset()
    with pytest.raises(ValueError, match=r"shape \(3,\), expected \(2,\)"):
        env.step(np.zeros(3))


# Quadruped goal ----------------------------------------------------------------------------------
@pytest.mark.parametrize("goal,radius", [([0.3, 0.0], 0.5), ([0.2, 0.1], 0.25), ([2.0, 0.0], 0.5)])
def test_quadruped_reward_recomputed_from_torso_position(goal, radius):
    env = suite.load("quadruped_goal_sparse", seed=1, goal=goal, goal_radius=radius, privileged=True)
    ts = env.reset()
    np.testing.assert_array_equal(ts.observation["task"], goal)
    np.testing.assert_array_equal(ts.observation["position"], [0.0, 0.0])  # starts at the origin
    assert ts.observation["torso_upright"] == pytest.approx(1.0)  # upright, random heading
    rng = np.random.default_rng(0)
    rewards = []
    for _ in range(60):
        step = env.step(rng.uniform(-1, 1, 12))
        distance = np.hypot(*(env.physics.named.data.xpos["torso", :2] - goal))
        assert step.reward == float(distance <= radius)
        rewards.append(step.reward)
    assert (sum(rewards) > 0) == (goal[0] < 1.0)  # random flailing stays near the start


def test_quadruped_goal_prior_on_circle_and_random_headings():
    headings = []
    for seed in range(6):
        env = suite.load("quadruped_goal_sparse", seed=seed, privileged=True)
        obs = env.reset().observation
        assert np.linalg.norm(obs["task"]) == pytest.approx(2.0)
        headings.append(obs["heading"])
    np.testing.assert_allclose(np.linalg.norm(headings, axis=1), 1.0, atol=1e-6)
    assert np.ptp(np.arctan2(*np.array(headings).T[::-1])) > 1.0


def test_hyperx_horizons_and_the_antgoal_variant():
    """The HyperX reference's settings: sparse point robot 100 steps × 3 MDP episodes, cheetah-dir 200 × 1,
    AntGoal's goals uniform in a 3 m disc, rewarded within 0.75 m, 6 MDP episodes of 10 s."""
    for name, horizon in (("point_robot_sparse", (100, 3)), ("cheetah_dir_sparse", (200, 1))):
        task = suite.load(name, seed=0).task
        assert (task.episode_length, task.episodes_per_task) == horizon
    env = suite.load("quadruped_antgoal_sparse", seed=0, privileged=True)
    assert (env.task.episode_length, env.task.episodes_per_task, env.task.goal_radius) == (500, 6, 0.75)
    assert env.control_timestep() * env.task.episode_length == pytest.approx(10.0)
    rng = np.random.default_rng(0)
    goals = np.array([env.task.prior.sample(rng) for _ in range(4000)])
    radii = np.linalg.norm(goals, axis=1)
    assert radii.max() <= 3.0 and np.mean(radii <= 1.5) == pytest.approx(0.25, abs=0.03)  # uniform in area
    # The batch draws the same goals as the environments.
    vec = suite.batch("quadruped_antgoal_sparse", 2, seed=4, privileged=True, episode_length=5)
    first = vec.reset().observation["task"]
    for i, s in enumerate(suite.spawn_seeds(4, 2)):
        np.testing.assert_array_equal(
            suite.load("quadruped_antgoal_sparse", seed=s, privileged=True).reset().observation["task"], first[i]
        )
    with pytest.raises(ValueError, match="goal_region must be one of circle, disc"):
        suite.load("quadruped_goal_sparse", goal_region="square")


# Learning on an easy setting -----------------------------------------------------------------------
def test_task_aware_ppo_learns_to_reach_the_dense_point_robot_goal():
    """100k frames (~30 s): from standing at the origin (return ≈ −100: distance 1 for 100 steps) to
    moving onto the goal. Measured: −17 to −37 per held-out goal (seed 0)."""
    from hyperstate import agents
    from hyperstate.evaluation.deploy import deploy, evaluation_tasks

    goals = evaluation_tasks("point_robot", 8)
    settings = {"ppo.num_envs": 16, "ppo.rollout_length": 100}
    untrained = agents.make("task_aware", **settings)
    untrained.train("point_robot", frames=1, seed=0, progress=False)  # one iteration
    trained = agents.make("task_aware", **settings)
    trained.train("point_robot", frames=100_000, seed=0, progress=False)
    before = deploy(untrained, "point_robot", goals).rewards.sum(0)
    after = deploy(trained, "point_robot", goals).rewards.sum(0)
    assert before.mean() < -80
    assert after.mean() > -50 and np.all(after > before)


def test_point_tasks_top_down_view_draws_candidates_goal_and_each_episode(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hyperstate.evaluation import report
    from hyperstate.suite import scripted

    support = suite.task_prior("point_treasure_sparse").support()
    for name, circles in (("point_treasure_sparse", 4 + 1), ("point_robot_sparse", 1)):
        view = suite.top_down(name)
        assert view.key == "position" and view.extent == (-1.6, 1.6, -1.6, 1.6)  # the floor, walls at 1.5
        fig, ax = plt.subplots()
        view.draw_scene(ax, support[2])
        discs = [p for p in ax.patches if isinstance(p, matplotlib.patches.Circle)]
        assert len(discs) == circles and np.allclose(discs[-1].center, support[2])
        plt.close(fig)
    env = suite.load("point_treasure_sparse", seed=0, goal=support[3])
    rewards, obs = scripted.rollout(env, scripted.PointExplorer(support))
    data = {f"obs_{k}": v[:, None] for k, v in obs.items()} | {"tasks": support[3][None], "rewards": rewards[:, None]}
    record = {"agent": "scripted", "task": "point_treasure_sparse", "seed": 0}
    path = report._top_down_plot(data, record, suite.top_down("point_treasure_sparse"), tmp_path / "b.png", plt)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("name", ["point_robot_sparse", "rooms_sparse", "cheetah_dir_sparse", "quadruped_goal_sparse"])
def test_an_invalid_physics_state_raises_physics_error_in_the_batch_as_in_dm_control(name, tmp_path, monkeypatch):
    """A NaN velocity makes MuJoCo reset the simulation mid-step. dm_control's environment raises
    `PhysicsError` then; the fast batch must too, naming the copy, rather than carry on from the reset."""
    from dm_control.rl.control import PhysicsError

    monkeypatch.chdir(tmp_path)  # where MuJoCo writes its warning log, MUJOCO_LOG.TXT
    env = suite.load(name, seed=0)
    env.reset()
    env.physics.data.qvel[0] = np.nan
    with pytest.raises(PhysicsError):
        env.step(np.zeros(action_size(name)))

    batch = suite.batch(name, 3, seed=0, num_threads=1)
    batch.reset()
    batch.step(np.zeros((3, action_size(name))))  # healthy copies: no error
    batch._qvel[1, 0] = np.nan
    with pytest.raises(PhysicsError, match=r"in copies \[1\]; MuJoCo reset them mid-step"):
        batch.step(np.zeros((3, action_size(name))))
