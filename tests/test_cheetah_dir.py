"""cheetah_dir_sparse / cheetah_dir: rewards, beliefs, BAMDP horizon, determinism, batch equality."""

import unittest

import dm_env
import numpy as np
import pytest
from dm_env import test_utils

from hyperstate import suite
from hyperstate.suite.cheetah_dir import BACKWARD, FORWARD
from hyperstate.suite.scripted import gait

ZONE, COST_W, DT = 5.0, 0.05, 0.05


def rootx(env) -> float:
    return float(env.physics.named.data.qpos["rootx"][0])


def control_cost(action) -> float:
    """An independent formula for the task's control cost. The task sums squares (np.sum(np.square(a)));
    a dot product rounds differently on some CPUs (1 ulp), so compare the two to a relative 1e-12."""
    a = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
    return COST_W * float(a @ a)


def test_control_cost_formulas_agree_to_rounding_only():
    """Why reward tests compare to a tolerance: the task's sum of squares and a dot product are the same
    number up to rounding, and which way they round depends on the CPU's NumPy kernels (on AVX-512 they
    differ by an ulp in about a quarter of random 6-vectors). Both stay within a relative 1e-12."""
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, (10_000, 6))
    summed = np.array([np.sum(np.square(a)) for a in actions])
    dotted = np.array([a @ a for a in actions])
    np.testing.assert_allclose(summed, dotted, rtol=1e-12, atol=0.0)
    assert np.max(np.abs(summed - dotted) / np.spacing(dotted)) <= 4  # a few ulps, never more


def expected_reward(direction, x_before, x_after, x_start, action, zone=ZONE):
    """Independent recomputation of the reward from physics quantities."""
    cost = control_cost(action)
    velocity = (x_after - x_before) / DT
    return (direction * velocity if abs(x_after - x_start) >= zone else 0.0) - cost


# dm_env conformance ----------------------------------------------------------------------------
class _Conformance(test_utils.EnvironmentTestMixin):
    task_name = ""
    kwargs: dict = {}

    def make_object_under_test(self):
        return suite.load(self.task_name, seed=0, **self.kwargs)

    def make_action_sequence(self):
        # Long enough to reach the end of the BAMDP episode and the reset after it.
        rng = np.random.default_rng(0)
        for _ in range(12):
            yield rng.uniform(-1, 1, 6)


class SparseConformance(_Conformance, unittest.TestCase):
    task_name = "cheetah_dir_sparse"
    kwargs = {"episode_length": 5}


class DenseConformance(_Conformance, unittest.TestCase):
    task_name = "cheetah_dir"
    kwargs = {"episode_length": 3, "episodes_per_task": 2, "privileged": True}


@pytest.mark.parametrize("name", ["cheetah_dir_sparse", "cheetah_dir"])
def test_dm_control_battery(name):
    """The checks of dm_control's own suite_test, on our tasks."""
    env = suite.load(name, seed=3, episode_length=100, episodes_per_task=2, privileged=True)
    spec = env.observation_spec()
    rng = np.random.default_rng(0)
    first = env.reset()
    assert first.discount is None and first.reward is None
    assert set(first.observation) == set(spec)
    history = {k: [] for k in spec}
    previous = first.observation
    for _ in range(200):
        step = env.step(rng.uniform(-1, 1, 6))
        assert isinstance(step.reward, float)
        assert isinstance(step.discount, float) and 0.0 <= step.discount <= 1.0
        for k, v in step.observation.items():
            spec[k].validate(v)
            assert np.all(np.isfinite(v))
            assert not np.shares_memory(v, previous[k]), k
            history[k].append(v)
        previous = step.observation
    assert step.last()
    # No observation element is constant over a long run, but the privileged ones: within one BAMDP
    # episode the task is fixed and the belief is the prior (sparse: random actions never leave the
    # zone) or one-hot from the first step on (dense).
    expected_belief = (
        [0.5, 0.5]
        if name == "cheetah_dir_sparse"
        else [float(d > 0) for d in (-history["task"][0][0], history["task"][0][0])]
    )
    np.testing.assert_array_equal(np.array(history["belief"]), np.tile(expected_belief, (200, 1)))
    for k in set(spec) - {"task", "belief"}:
        values = np.array(history[k])
        assert np.all(values.std(axis=0) > 0), k
    # Two resets give different initial states.
    a, b = env.reset().observation, env.reset().observation
    assert not np.allclose(a["position"], b["position"])


# Rewards -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("direction", [FORWARD, BACKWARD])
def test_reward_recomputed_from_physics_along_scripted_run(direction):
    env = suite.load("cheetah_dir_sparse", seed=1, direction=direction)
    policy = gait(direction)
    env.reset()
    x_start = rootx(env)
    crossed_at = None
    rng = np.random.default_rng(0)
    for t in range(200):
        # Actions beyond the bounds exercise the clipping in the control cost.
        action = policy(t) * rng.uniform(0.9, 1.3, 6)
        x_before = rootx(env)
        step = env.step(action)
        x_after = rootx(env)
        want = expected_reward(direction, x_before, x_after, x_start, action)
        assert step.reward == pytest.approx(want, rel=1e-12, abs=1e-12)
        assert step.observation["x_displacement"][0] == pytest.approx(x_after - x_start, abs=1e-12)
        inside = abs(x_after - x_start) < ZONE
        if inside:  # the control cost alone, no velocity term
            assert step.reward == pytest.approx(-control_cost(action), rel=1e-12, abs=0.0)
        elif crossed_at is None:
            crossed_at = t
    assert crossed_at is not None, "scripted gait should leave the zone"
    assert abs(rootx(env) - x_start) > 10.0


def test_forward_run_earns_velocity_reward_only_after_crossing():
    env = suite.load("cheetah_dir_sparse", seed=1, direction=FORWARD)
    policy = gait(FORWARD)
    env.reset()
    x_start = rootx(env)
    rewards, costs, displacement = [], [], []
    for t in range(200):
        action = policy(t)
        step = env.step(action)
        rewards.append(step.reward)
        costs.append(control_cost(action))
        displacement.append(rootx(env) - x_start)
    rewards, costs, displacement = np.array(rewards), np.array(costs), np.array(displacement)
    velocity_terms = rewards + costs
    inside = np.abs(displacement) < ZONE
    assert inside[:20].all() and not inside.all()
    # Inside the zone the reward is the control cost alone (to rounding: the formulas differ).
    np.testing.assert_allclose(rewards[inside], -costs[inside], rtol=1e-12, atol=0.0)
    assert np.all(displacement[~inside] >= ZONE)  # left forward, never came back
    assert velocity_terms[~inside].sum() > 100.0  # running forward after crossing pays
    # The same run on a backward task is punished after the crossing instead.
    env = suite.load("cheetah_dir_sparse", seed=1, direction=BACKWARD)
    env.reset()
    rewards = np.array([env.step(policy(t)).reward for t in range(200)])
    cost = np.array([control_cost(policy(t)) for t in range(200)])
    np.testing.assert_allclose(rewards[~inside] + cost[~inside], -velocity_terms[~inside], rtol=1e-12)


def test_dense_variant_rewards_velocity_everywhere():
    env = suite.load("cheetah_dir", seed=2, direction=BACKWARD)
    env.reset()
    x_start = rootx(env)
    action = np.full(6, 0.5)
    x_before = rootx(env)
    step = env.step(action)
    want = expected_reward(BACKWARD, x_before, rootx(env), x_start, action, zone=0.0)
    assert step.reward == pytest.approx(want, rel=1e-12)
    assert step.reward != pytest.approx(-COST_W * 1.5)
    np.testing.assert_array_equal(env.task.belief, [1.0, 0.0])  # one reward reveals the direction


# Beliefs and the BAMDP horizon --------------------------------------------------------------------
def test_belief_prior_until_crossing_then_one_hot_and_held_across_inner_episodes():
    env = suite.load("cheetah_dir_sparse", seed=4, direction=BACKWARD, episodes_per_task=3, privileged=True)
    policy = gait(BACKWARD)
    step = env.reset()
    np.testing.assert_array_equal(step.observation["belief"], [0.5, 0.5])
    np.testing.assert_array_equal(step.observation["task"], [BACKWARD])
    x_start, crossed, t, boundaries = rootx(env), False, 0, []
    inner = 0
    while not step.last():
        # Run backward in the first MDP episode only; stand still (zero action) afterwards.
        action = policy(t) if inner == 0 else np.zeros(6)
        step = env.step(action)
        t += 1
        new_inner = int(step.observation["inner_episode"][0])
        if new_inner != inner:
            boundaries.append(t)
            inner = new_inner
            x_start = rootx(env)
            assert step.observation["x_displacement"][0] == 0.0  # physics and x0 were reset
        elif not crossed and abs(rootx(env) - x_start) >= ZONE:
            crossed = True
        want = [1.0, 0.0] if crossed else [0.5, 0.5]
        np.testing.assert_array_equal(step.observation["belief"], want)
        np.testing.assert_array_equal(env.task.belief, want)
        np.testing.assert_array_equal(step.observation["task"], [BACKWARD])
    assert crossed and boundaries == [200, 400] and t == 600
    assert step.discount == 1.0  # the horizon truncates
    # A new BAMDP episode starts from the prior again.
    first = env.reset()
    np.testing.assert_array_equal(first.observation["belief"], [0.5, 0.5])
    assert first.observation["inner_episode"][0] == 0.0


def test_privileged_keys_only_on_request():
    plain = suite.load("cheetah_dir_sparse", seed=0).reset().observation
    assert set(plain) == {"position", "velocity", "x_displacement", "inner_episode"}
    assert plain["position"].shape == (8,) and plain["velocity"].shape == (9,)


# Determinism and the prior -------------------------------------------------------------------------
def _trajectory(seed, steps=30):
    env = suite.load("cheetah_dir_sparse", seed=seed, privileged=True, episode_length=10)
    rng = np.random.default_rng(123)
    out = [env.reset().observation]
    for _ in range(steps):
        step = env.step(rng.uniform(-1, 1, 6))
        out.append({**step.observation, "reward": np.array([step.reward or 0.0])})
    return out


def test_same_seed_same_trajectory_different_seed_different():
    a, b, c = _trajectory(7), _trajectory(7), _trajectory(8)
    for x, y in zip(a, b, strict=True):
        for k in x:
            np.testing.assert_array_equal(x[k], y[k])
    assert not all(np.array_equal(x["position"], y["position"]) for x, y in zip(a, c, strict=True))


def test_prior_is_fair_and_seeded():
    env = suite.load("cheetah_dir_sparse", seed=11, privileged=True, episode_length=1)
    draws = [env.reset().observation["task"][0] for _ in range(400)]
    assert set(draws) == {FORWARD, BACKWARD}
    forward = np.mean(np.array(draws) == FORWARD)
    assert abs(forward - 0.5) < 0.1  # 400 fair draws: std 0.025
    # Across seeds too.
    tasks = [
        suite.load("cheetah_dir_sparse", seed=s, privileged=True).reset().observation["task"][0] for s in range(200)
    ]
    assert abs(np.mean(np.array(tasks) == FORWARD) - 0.5) < 0.125
    # The prior never touches numpy's global generator.
    np.random.seed(0)
    before = np.random.get_state()[1].copy()
    suite.load("cheetah_dir_sparse", seed=None).reset()
    np.testing.assert_array_equal(np.random.get_state()[1], before)


# Batched simulator ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name,kwargs",
    [
        ("cheetah_dir_sparse", {"episode_length": 200}),
        ("cheetah_dir", {"episode_length": 40, "episodes_per_task": 2}),
    ],
)
def test_batch_equals_dm_control_step_for_step(name, kwargs):
    n, seed = 4, 21
    vec = suite.batch(name, n, seed=seed, privileged=True, **kwargs)
    envs = [suite.load(name, seed=s, privileged=True, **kwargs) for s in suite.spawn_seeds(seed, n)]
    batch_step = vec.reset()
    for env in envs:
        env.reset()
    rng = np.random.default_rng(5)
    gaits = [gait(FORWARD), gait(BACKWARD), gait(FORWARD), None]
    steps_per_bamdp = kwargs["episode_length"] * kwargs.get("episodes_per_task", 1)
    resets, crossed = 0, False
    for t in range(steps_per_bamdp + 30):
        # Scripted runners leave the zone; the last copy acts randomly (and out of bounds).
        action = np.stack([g(t % kwargs["episode_length"]) if g else rng.uniform(-1.5, 1.5, 6) for g in gaits])
        batch_step = vec.step(action)
        for i, env in enumerate(envs):
            step = env.step(action[i])
            assert step.reward == batch_step.reward[i]
            assert step.last() == batch_step.last[i]
            for k, v in step.observation.items():
                np.testing.assert_array_equal(batch_step.final_observation[k][i], v, err_msg=k)
            if step.last():
                resets += 1
                step = env.reset()
            for k, v in step.observation.items():
                np.testing.assert_array_equal(batch_step.observation[k][i], v, err_msg=k)
            crossed |= step.observation["belief"].max() == 1.0
    assert resets == n and crossed


def test_loop_batch_matches_fast_batch():
    kwargs = {"episode_length": 15, "episodes_per_task": 2, "privileged": True}
    fast = suite.batch("cheetah_dir_sparse", 3, seed=9, **kwargs)
    slow = suite.LoopBatch([suite.load("cheetah_dir_sparse", seed=s, **kwargs) for s in suite.spawn_seeds(9, 3)])
    a, b = fast.reset(), slow.reset()
    rng = np.random.default_rng(0)
    for _ in range(35):
        action = rng.uniform(-1, 1, (3, 6))
        a, b = fast.step(action), slow.step(action)
        np.testing.assert_array_equal(a.reward, b.reward)
        np.testing.assert_array_equal(a.last, b.last)
        for k in a.observation:
            np.testing.assert_array_equal(a.observation[k], b.observation[k])
            np.testing.assert_array_equal(a.final_observation[k], b.final_observation[k])
    assert fast.observation_spec() == slow.observation_spec()


# Bad input -------------------------------------------------------------------------------------------
def test_bad_actions_raise_clear_errors():
    env = suite.load("cheetah_dir_sparse", seed=0)
    env.reset()
    with pytest.raises(ValueError, match=r"shape \(5,\), expected \(6,\)"):
        env.step(np.zeros(5))
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.array([0, 0, np.nan, 0, 0, 0]))
    vec = suite.batch("cheetah_dir_sparse", 2, seed=0)
    with pytest.raises(RuntimeError, match="reset"):
        vec.step(np.zeros((2, 6)))
    vec.reset()
    with pytest.raises(ValueError, match=r"shape \(6,\), expected \(2, 6\)"):
        vec.step(np.zeros(6))
    with pytest.raises(ValueError, match=r"NaN or inf \(in copies \[1\]\)"):
        vec.step(np.array([np.zeros(6), np.full(6, np.inf)]))


def test_bad_task_arguments_raise_clear_errors():
    with pytest.raises(ValueError, match="direction must be"):
        suite.load("cheetah_dir_sparse", direction=0.5)
    with pytest.raises(ValueError, match="episodes_per_task"):
        suite.load("cheetah_dir_sparse", episodes_per_task=0)
    with pytest.raises(ValueError, match="zone_radius"):
        suite.load("cheetah_dir_sparse", zone_radius=-1.0)
    with pytest.raises(ValueError, match="non-negative"):
        suite.load("cheetah_dir_sparse", seed=-3)
    with pytest.raises(TypeError, match="'zone_raduis'"):
        suite.batch("cheetah_dir_sparse", 2, zone_raduis=3.0)
    with pytest.raises(ValueError, match="num_envs"):
        suite.batch("cheetah_dir_sparse", 0)


def test_forced_direction_and_zone_kwargs():
    env = suite.load("cheetah_dir_sparse", seed=0, direction=FORWARD, zone_radius=0.5, privileged=True)
    assert all(env.reset().observation["task"][0] == FORWARD for _ in range(5))
    assert isinstance(env, dm_env.Environment)
    assert env.task.zone_radius == 0.5 and env.task.direction == FORWARD


def test_set_tasks_forces_each_copy_and_prior_resumes():
    fast = suite.batch("cheetah_dir_sparse", 3, seed=0, privileged=True, episode_length=2)
    slow = suite.LoopBatch(
        [suite.load("cheetah_dir_sparse", seed=s, privileged=True, episode_length=2) for s in suite.spawn_seeds(0, 3)]
    )
    for vec in (fast, slow):
        vec.set_tasks(np.array([[FORWARD], [BACKWARD], [FORWARD]]))
        np.testing.assert_array_equal(vec.reset().observation["task"][:, 0], [FORWARD, BACKWARD, FORWARD])
        vec.step(np.zeros((3, 6)))
        out = vec.step(np.zeros((3, 6)))  # auto-reset keeps the forced tasks
        assert out.last.all()
        np.testing.assert_array_equal(out.observation["task"][:, 0], [FORWARD, BACKWARD, FORWARD])
        with pytest.raises(ValueError, match="one task per copy"):
            vec.set_tasks(np.ones((2, 1)))
        with pytest.raises(ValueError, match="direction must be"):
            vec.set_tasks(np.zeros((3, 1)))
        vec.set_tasks(None)
        draws = np.concatenate([vec.reset().observation["task"][:, 0] for _ in range(20)])
        assert set(draws) == {FORWARD, BACKWARD}


def test_zone_exploration_metrics_on_known_trajectories():
    metrics = suite.exploration_metrics("cheetah_dir_sparse")
    x = np.array(
        [
            [0.5, 1.0, -2.0, 1.0],
            [0.5, 3.0, -6.0, 5.0],
            [0.5, 5.5, -3.0, 9.0],
            [0.5, 7.0, -1.0, 12.0],
        ]
    )[..., None]  # (T=4, M=4): stays; exits forward at step 3; exits backward then returns; exits at step 2
    tasks = np.array([[FORWARD], [FORWARD], [FORWARD], [BACKWARD]])
    m = metrics({"x_displacement": x}, np.zeros((4, 4)), tasks)
    np.testing.assert_array_equal(m["left_zone"], [0, 1, 1, 1])
    np.testing.assert_array_equal(m["first_exit_step"], [np.nan, 3, 2, 2])
    np.testing.assert_array_equal(m["correct_direction"], [0, 1, 0, 0])
    np.testing.assert_array_equal(m["stuck"], [0, 0, 1, 0])
    np.testing.assert_array_equal(m["distance_correct"], [0.5, 7.0, -1.0, -12.0])
    # The dense task has no zone: every deployment "leaves" it on its first step.
    dense = suite.exploration_metrics("cheetah_dir")({"x_displacement": x}, np.zeros((4, 4)), tasks)
    np.testing.assert_array_equal(dense["first_exit_step"], [1, 1, 1, 1])


def test_turn_around_metrics_on_known_trajectories():
    metrics = suite.exploration_metrics("cheetah_dir_sparse")
    x = np.array(
        [
            [0.5, 1.0, -2.0, 1.0, 3.0],
            [0.5, 6.0, -6.0, 6.0, 6.0],
            [0.5, 8.0, -3.0, 9.0, -3.0],
            [0.5, 9.0, -1.0, 12.0, -7.0],
        ]
    )[..., None]
    # Forward tasks: stays; exits forward; exits backward and comes back. Backward tasks: exits forward and
    # keeps going; exits forward, turns around and ends beyond the backward border.
    tasks = np.array([[FORWARD], [FORWARD], [FORWARD], [BACKWARD], [BACKWARD]])
    rewards = np.tile(np.arange(1.0, 6.0), (4, 1))  # returns 4, 8, 12, 16, 20
    m = metrics({"x_displacement": x}, rewards, tasks)
    nan = np.nan
    np.testing.assert_array_equal(m["wrong_first_exit"], [nan, 0, 1, 1, 1])
    np.testing.assert_array_equal(m["turned_around"], [nan, nan, 0, 0, 1])
    np.testing.assert_array_equal(m["correct_direction"], [0, 1, 0, 0, 1])
    np.testing.assert_array_equal(m["return_forward"], [4, 8, 12, nan, nan])
    np.testing.assert_array_equal(m["return_backward"], [nan, nan, nan, 16, 20])
    np.testing.assert_array_equal(m["return_wrong_first"], [nan, nan, 12, 16, 20])


def test_loop_batch_snapshot_restores_exactly():
    def make():
        return suite.LoopBatch(
            [
                suite.load("cheetah_dir_sparse", seed=s, privileged=True, episode_length=30)
                for s in suite.spawn_seeds(4, 2)
            ]
        )

    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (70, 2, 6))
    original = make()
    original.reset()
    for a in actions[:40]:
        original.step(a)
    snapshot = original.state_dict()
    expected = [original.step(a) for a in actions[40:]]
    restored = make()
    restored.reset()
    restored.load_state_dict(snapshot)
    for a, want in zip(actions[40:], expected, strict=True):
        got = restored.step(a)
        np.testing.assert_array_equal(got.reward, want.reward)
        for k in want.observation:
            np.testing.assert_array_equal(got.observation[k], want.observation[k])
