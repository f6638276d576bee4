"""The quadruped-goal fast batch (`QuadrupedGoalBatch`) against its dm_control environment, step for step.

Copy i of `suite.batch(NAME, n, seed)` must equal `suite.load(NAME, seed=spawn_seeds(seed, n)[i])` to the
bit: initial heights and headings, every observation key, rewards, last flags and final observations,
across MDP and BAMDP episode ends, with forced tasks, and after a snapshot round trip.
"""

import copy

import mujoco
import numpy as np

from hyperstate import suite
from hyperstate.suite.quadruped_goal import GOAL_DISTANCE, QuadrupedGoalBatch

NAME = "quadruped_goal_sparse"
N, SEED = 3, 13
KWARGS = {"episode_length": 30, "episodes_per_task": 2, "privileged": True}
BAMDP_STEPS = KWARGS["episode_length"] * KWARGS["episodes_per_task"]
# Copy 0's goal is where it stands (rewarded at once), copy 1's on the rewarded disc's border (the
# random walk crosses it), copy 2's out of reach.
NEAR_GOALS = np.array([[0.1, 0.05], [0.0, 0.5], [-GOAL_DISTANCE, 0.0]])


def assert_same(batch_obs: dict, i: int, obs: dict, when: str) -> None:
    assert set(batch_obs) == set(obs), when
    for k, v in obs.items():
        np.testing.assert_array_equal(batch_obs[k][i], v, err_msg=f"{when}: {k}")


def assert_same_physics(vec, envs, when: str) -> None:
    """The batch's state rows are the environments' full integration states (height, warm start, ...)."""
    rows = vec.state_dict()["physics"]
    for i, env in enumerate(envs):
        model, data = env.physics.model.ptr, env.physics.data.ptr
        state = np.empty(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_INTEGRATION))
        mujoco.mj_getState(model, data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
        np.testing.assert_array_equal(rows[i], state, err_msg=f"{when}: copy {i}")


def test_batch_equals_dm_control_step_for_step_with_forced_goals_and_prior():
    vec = suite.batch(NAME, N, seed=SEED, **KWARGS)
    assert isinstance(vec, QuadrupedGoalBatch)
    envs = [suite.load(NAME, seed=s, **KWARGS) for s in suite.spawn_seeds(SEED, N)]
    assert vec.observation_spec() == dict(envs[0].observation_spec())
    vec.set_tasks(NEAR_GOALS)
    for env, goal in zip(envs, NEAR_GOALS, strict=True):
        env.task.force_task(goal)
    first = vec.reset()
    for i, env in enumerate(envs):
        assert_same(first.observation, i, env.reset().observation, "reset")
    assert_same_physics(vec, envs, "reset")
    np.testing.assert_array_equal(vec.task_parameters, NEAR_GOALS)

    rng = np.random.default_rng(3)
    rewards, resets, tasks = [], 0, []
    for t in range(2 * BAMDP_STEPS + 10):  # two BAMDP episodes of two MDP episodes each, then a few steps
        action = rng.uniform(-1.2, 1.2, (N, 12))  # out of the control range at times: clipped
        out = vec.step(action)
        for i, env in enumerate(envs):
            step = env.step(action[i])
            assert step.reward == out.reward[i], (t, i)
            assert step.last() == out.last[i], (t, i)
            assert_same(out.final_observation, i, step.observation, f"step {t}, final")
            if step.last():
                resets += 1
                step = env.reset()
            assert_same(out.observation, i, step.observation, f"step {t}")
        assert_same_physics(vec, envs, f"step {t}")
        rewards.append(out.reward)
        if out.last.any():
            tasks.append(out.observation["task"].copy())
            if len(tasks) == 1:  # forced goals held for the second BAMDP episode; the prior from the third
                vec.set_tasks(None)
                for env in envs:
                    env.task.force_task(None)
    rewards = np.array(rewards)
    assert resets == 2 * N
    assert rewards[:BAMDP_STEPS, 0].all() and rewards[:BAMDP_STEPS, 2].sum() == 0
    assert 0 < rewards[:BAMDP_STEPS, 1].sum() < BAMDP_STEPS  # the random walk crosses the disc's border
    np.testing.assert_array_equal(tasks[0], NEAR_GOALS)
    np.testing.assert_allclose(np.linalg.norm(tasks[1], axis=1), GOAL_DISTANCE)  # drawn from the prior
    # The MDP episodes start at the origin with different headings, at the lowest height without contacts.
    heading = first.observation["heading"]
    assert np.all(np.abs(first.observation["position"]) < 1e-3) and len({tuple(h) for h in heading}) == N


def test_snapshot_continues_identically_across_episode_ends():
    kwargs = {"episode_length": 8, "episodes_per_task": 2}
    vec = suite.batch(NAME, N, seed=SEED, **kwargs)
    vec.reset()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (40, N, 12))
    for a in actions[:5]:
        vec.step(a)
    snapshot = copy.deepcopy(vec.state_dict())
    expected = [vec.step(a) for a in actions[5:]]  # crosses MDP and BAMDP ends: new headings and goals
    assert any(e.last.any() for e in expected)
    for restored in (vec, suite.batch(NAME, N, seed=SEED + 1, **kwargs)):
        restored.load_state_dict(snapshot)
        for a, want in zip(actions[5:], expected, strict=True):
            got = restored.step(a)
            np.testing.assert_array_equal(got.reward, want.reward)
            np.testing.assert_array_equal(got.last, want.last)
            for k in want.observation:
                np.testing.assert_array_equal(got.observation[k], want.observation[k], err_msg=k)
                np.testing.assert_array_equal(got.final_observation[k], want.final_observation[k], err_msg=k)


def test_goal_metrics_and_success_on_known_rewards():
    """Six MDP episodes of 4 steps: deployment 0 is rewarded at step 6 and through the last episode,
    deployment 1 never; the antgoal criterion needs the return, the one-episode task only the find."""
    from hyperstate.suite.quadruped_goal import goal_metrics

    rewards = np.zeros((24, 2))
    rewards[5, 0] = 1.0
    rewards[21:, 0] = 1.0  # 3 of the last episode's 4 steps
    observations = {
        "position": np.zeros((24, 2, 2)),
        "inner_episode": np.repeat(np.arange(6.0), 4)[:, None, None] * np.ones((1, 2, 1)),
    }
    m = goal_metrics(observations, rewards, np.array([[1.0, 0.0], [0.0, 2.0]]))
    np.testing.assert_array_equal(m["goal_reached"], [1.0, 0.0])
    np.testing.assert_array_equal(m["first_goal_step"], [6.0, np.nan])
    np.testing.assert_allclose(m["closest_distance"], [1.0, 2.0])
    np.testing.assert_allclose(m["last_episode_at_goal"], [0.75, 0.0])

    antgoal, goal = suite.success("quadruped_antgoal_sparse"), suite.success("quadruped_goal_sparse")
    assert antgoal({"goal_reached": 0.95, "last_episode_at_goal": 0.6})
    assert not antgoal({"goal_reached": 0.95, "last_episode_at_goal": 0.4})
    assert not antgoal({"goal_reached": 0.85, "last_episode_at_goal": 0.9})
    assert goal({"goal_reached": 0.9}) and not goal({"goal_reached": 0.85})
