"""Rooms: the maze's walls, the reference's staged reward recomputed on the grid, the exact belief over
the 48 tasks, the metrics and the prior."""

import numpy as np
import pytest

from hyperstate import suite
from hyperstate.suite import rooms, scripted

CELL = rooms.CELL


def reference_reward(cell, goals, reached):
    """The HyperX reference's RoomNavi reward for one grid cell (its if/elif chain), halved; `reached`
    is updated in place."""
    g1, g2, g3 = (tuple(goals[k]) for k in range(3))
    if cell == g1:
        reached[0] = True
        return 0.5
    if reached[0] and cell == g2:
        reached[1] = True
        return 5.0
    if reached[1] and cell == g3:
        reached[2] = True
        return 50.0
    return -0.05


class Driver:
    """Drives the point mass through waypoints with a damped proportional controller."""

    def __init__(self, env):
        self.env = env
        self.ts = env.reset()
        self.rewards, self.positions, self.beliefs = [], [], []

    def to(self, target, steps=40, tolerance=0.03):
        for _ in range(steps):
            p, v = self.ts.observation["position"], self.ts.observation["velocity"]
            if np.linalg.norm(p - target) < tolerance and np.linalg.norm(v) < 0.3:
                return
            self.ts = self.env.step(np.clip(8.0 * (np.asarray(target) - p) - 0.8 * v, -1, 1))
            self.rewards.append(self.ts.reward)
            self.positions.append(self.ts.observation["position"])
            if "belief" in self.ts.observation:
                self.beliefs.append(self.ts.observation["belief"])

    @property
    def position(self):
        return self.ts.observation["position"]


def test_walls_confine_the_point_to_rooms_and_corridors():
    driver = Driver(suite.load("rooms_sparse", seed=0, episode_length=400))
    driver.to((0.2, 0.2))
    driver.to((0.8, 0.2), steps=30)  # into the block beside the right corridor
    assert driver.position[0] < 0.3  # stopped at the middle room's border
    driver.to((0.2, 0.0))
    driver.to((0.6, 0.0))
    driver.to((0.6, 0.25), steps=30)  # up out of the corridor
    assert abs(driver.position[1]) < 0.1
    driver.to((1.45, 0.0), steps=60)
    driver.to((2.0, 0.0), steps=30)  # through the outer wall
    assert 1.3 < driver.position[0] < 1.5
    visited = np.array(driver.positions)
    assert np.abs(visited[:, 1]).max() < 0.3 and np.abs(visited[:, 0]).max() < 1.5


def test_prior_is_the_references_48_tasks():
    support = rooms.task_support()
    cells = np.round(support / CELL).astype(int).reshape(-1, 3, 2)
    assert len({tuple(c.ravel()) for c in cells}) == 48
    middle = {(-1, 1), (-1, -1), (1, 1), (1, -1)}
    for g1, g2, g3 in cells:
        assert tuple(g1) in middle and tuple(g3) in middle and tuple(g3) != tuple(g1)
        assert abs(g2[1]) == 1 and abs(g2[0]) in (5, 7) and np.sign(g2[0]) == np.sign(g1[0])
    np.testing.assert_allclose(rooms.RoomsPrior().probabilities(), np.full(48, 1 / 48))
    rng = np.random.default_rng(0)
    draws = {tuple(rooms.RoomsPrior().sample(rng)) for _ in range(2000)}
    assert len(draws) == 48
    with pytest.raises(ValueError, match="one of the prior's 48 tasks"):
        suite.load("rooms_sparse", seed=0, goals=[0.2, 0.2, -1.0, 0.2, -0.2, -0.2])  # goal 2 on the wrong side


def tour(goals):
    """Waypoints that visit goal 1, goal 2 and goal 3 through the corridor on goal 1's side."""
    g1, g2, g3 = goals[:2], goals[2:4], goals[4:]
    door = np.sign(g1[0]) * np.array([0.2, 0.0]), np.sign(g1[0]) * np.array([1.0, 0.0])
    return [g1, door[0], door[1], g2, door[1], door[0], g3]


def test_staged_reward_is_the_references_and_the_belief_is_exact():
    support = rooms.task_support()
    goals = support[17]
    env = suite.load("rooms_sparse", seed=0, goals=goals, privileged=True, episode_length=400)
    driver = Driver(env)
    np.testing.assert_allclose(driver.ts.observation["belief"], np.full(48, 1 / 48))
    # First a wrong middle corner, then the tour.
    wrong = next(c for c in rooms.MIDDLE_CORNERS if c != tuple(np.round(goals[:2] / CELL)) and c[0] * goals[0] > 0)
    driver.to(CELL * np.array(wrong))
    for waypoint in tour(goals):
        driver.to(waypoint, steps=60)
    driver.to(goals[4:], steps=10)  # stay on goal 3
    cells = [tuple(c) for c in np.round(np.array(driver.positions) / CELL).astype(int)]
    goal_cells = np.round(goals.reshape(3, 2) / CELL).astype(int)
    reached = [False, False, False]
    expected = [reference_reward(c, goal_cells, reached) for c in cells]
    np.testing.assert_allclose(driver.rewards, expected)
    assert reached == [True, True, True] and driver.rewards[-1] == 50.0
    # The belief: a wrong corner rules out its 12 tasks; each stage's reward halves what is left to learn.
    beliefs = np.array(driver.beliefs)
    alive = (beliefs > 0).sum(axis=1)
    rewards = np.array(driver.rewards)
    assert alive[np.argmax(rewards == 0.5) - 1] == 36
    assert alive[np.argmax(rewards == 0.5)] == 12  # goal 1 known: 4 × 3 left
    assert alive[np.argmax(rewards == 5.0)] == 3  # goal 2 known
    assert alive[-1] == 1 and beliefs[-1, 17] == 1.0
    for b, n in zip(beliefs, alive, strict=True):
        np.testing.assert_allclose(b[b > 0], 1 / n)
    # The metrics recompute the stages from positions.
    obs = {"position": np.array(driver.positions)[:, None], "inner_episode": np.zeros((len(cells), 1, 1))}
    metrics = rooms.rooms_metrics(obs, rewards[:, None], goals[None])
    assert metrics["goals_reached"][0] == 3
    firsts = [metrics[f"first_goal_{k}_step"][0] for k in (1, 2, 3)]
    assert firsts == [np.argmax(rewards == r) + 1.0 for r in (0.5, 5.0, 50.0)]
    assert rooms.all_three_goals({k: float(v[0]) for k, v in metrics.items()})


def test_goal_two_pays_only_after_goal_one_and_stages_reset_each_mdp_episode():
    support = rooms.task_support()
    goals = support[0]  # goal 1 (-1, 1), goal 2 (-7, 1)
    env = suite.load("rooms_sparse", seed=0, goals=goals, privileged=True, episode_length=120, episodes_per_task=2)
    driver = Driver(env)
    for waypoint in tour(goals)[1:4]:  # straight to goal 2, skipping goal 1
        driver.to(waypoint, steps=60)
    assert 5.0 not in driver.rewards and set(driver.rewards) == {-0.05}
    # Goal 2's cell visited before goal 1 pays the step penalty whatever the task: it tells nothing (and
    # the path through the corridor touched no middle-room corner).
    np.testing.assert_allclose(driver.beliefs[-1], np.full(48, 1 / 48))
    while driver.ts.observation["inner_episode"][0] == 0:
        driver.ts = env.step(np.zeros(2))
        driver.rewards.append(driver.ts.reward)
    assert env.task.reached.tolist() == [False, False, False]
    np.testing.assert_array_equal(driver.position, [0.0, 0.0])


class _StayOnGoalOne(scripted.RoomsExplorer):
    """The naive strategy: find goal 1, then stay on it (what a learner stops at that never looks further)."""

    def _next_target(self, position):
        return self.goals[0] if self.stage >= 1 else super()._next_target(position)


def test_scripted_explorer_solves_nearly_every_task_and_beats_staying_on_goal_one():
    """The docs' scripted lower bound: trying corners stage by stage reaches all three goals, and visiting
    the goals in order pays far more than collecting goal 1's small reward."""
    support = rooms.task_support()
    reached, returns, naive = [], [], []
    for k in range(0, 48, 3):
        env = suite.load("rooms_sparse", seed=0, goals=support[k])
        rewards, obs = scripted.rollout(env, scripted.RoomsExplorer())
        metrics = rooms.rooms_metrics(
            {"position": obs["position"][:, None], "inner_episode": obs["inner_episode"][:, None]},
            rewards[:, None],
            support[k][None],
        )
        reached.append(metrics["goals_reached"][0])
        returns.append(rewards.sum())
        naive_rewards, _ = scripted.rollout(env, _StayOnGoalOne())
        assert set(naive_rewards) <= {0.5, -0.05}  # never paid for goal 2 or 3
        naive.append(naive_rewards.sum())
    assert np.mean(np.array(reached) == 3) >= 0.85 and np.mean(returns) > 800
    assert np.mean(returns) > 10 * np.mean(naive) > 0
