"""Mountain Treasure: the reference's motion and reward recomputed by hand, the Bayes-optimal climb,
the exact belief, the metrics and the top-down behaviour plot."""

import numpy as np
import pytest

from hyperstate import suite
from hyperstate.evaluation import report
from hyperstate.suite import mountain_treasure as mt
from hyperstate.suite import scripted

K8 = "mountain_treasure_k8_sparse"


def reference_reward(position, treasure, treasure_reward=10.0, penalty=-5.0, height=1.0):
    """The HyperX reference's TreasureHunt reward, written as it is there (one position, if/elif)."""
    top = float(np.sqrt(position[0] ** 2 + position[1] ** 2))
    if top <= 0.5:
        return height * (-0.5 + top) + penalty
    if np.sqrt(((position - treasure) ** 2).sum()) <= 0.1:
        return treasure_reward
    return penalty * max(1.0, top)


def run(env, actions):
    """Rewards and positions of one BAMDP episode driven by `actions(step, observation)`."""
    ts = env.reset()
    rewards, positions, maps = [], [], []
    while not ts.last():
        ts = env.step(actions(len(rewards), ts.observation))
        rewards.append(ts.reward)
        positions.append(ts.observation["position"])
        maps.append(ts.observation["treasure_map"])
    return np.array(rewards), np.array(positions), np.array(maps)


def test_motion_reward_and_map_are_the_references():
    env = suite.load("mountain_treasure_sparse", seed=5, privileged=True)
    rng = np.random.default_rng(0)

    # A walk that crosses the mountain, the circle and the arena's border; actions beyond ±1 are clipped.
    def drift(t):  # up across the mountain to the border, then right along it; beyond ±1 is clipped
        return rng.uniform(-0.6, 0.6, 2) + ((0.0, 1.0) if t < 40 else (1.0, 0.0))

    rewards, positions, maps = run(env, lambda t, obs: drift(t))
    treasure = env.task.task_parameters
    position = np.array(mt.START)
    rng = np.random.default_rng(0)
    for t in range(len(rewards)):
        action = np.clip(drift(t), -1, 1)
        position = np.clip(position + 0.1 * action, -1.5, 1.5)
        np.testing.assert_allclose(positions[t], position, atol=1e-12)
        assert rewards[t] == pytest.approx(reference_reward(positions[t], treasure), abs=1e-12)
        seen = np.linalg.norm(positions[t]) < 0.1
        np.testing.assert_array_equal(maps[t], treasure if seen else np.zeros(2))
    assert len(rewards) == 100 and np.abs(positions).max() == 1.5  # reached a border, clipped there
    assert (np.linalg.norm(positions, axis=1) <= 0.5).any()  # crossed the mountain
    # The reference's class defaults are one keyword argument away.
    small = suite.load("mountain_treasure_sparse", seed=5, treasure_reward=1.0, step_penalty=1.0)
    r_small, p_small, _ = run(small, lambda t, obs: np.array([0.0, 1.0]))
    assert r_small == pytest.approx([reference_reward(p, small.task.task_parameters, 1.0, -1.0) for p in p_small])


class _Strategy:
    """A scripted strategy as `run`'s `actions(step, observation)` (reward unused by the climber)."""

    def __init__(self, strategy):
        self.strategy = strategy
        strategy.reset()

    def __call__(self, t, obs):
        if t == 0:
            self.strategy.reset()
        return self.strategy.act(obs, 0.0)


def test_climbing_beats_walking_the_circle_on_average():
    """The scripted bracket of the docs: the climber reads the map in every task and beats the circle
    walker (what a meta-learner that does not explore does) on average, not in every task."""
    climbs, walks = [], []
    for angle in np.linspace(0, 2 * np.pi, 16, endpoint=False):
        env = suite.load("mountain_treasure_sparse", seed=0, treasure=[np.cos(angle), np.sin(angle)])
        for strategy, returns, climbed in (
            (scripted.MountainClimber(), climbs, 1),
            (scripted.CircleWalker(), walks, 0),
        ):
            rewards, obs = scripted.rollout(env, strategy)
            returns.append(rewards.sum())
            positions = {"position": obs["position"][:, None]}
            metrics = mt.treasure_metrics(positions, rewards[:, None], env.task.task_parameters[None])
            assert metrics["reached_top"][0] == climbed and metrics["treasure_reached"][0] == 1
    climbs, walks = np.array(climbs), np.array(walks)
    assert climbs.min() > 700 and np.mean(climbs) > np.mean(walks) + 100
    assert (walks > climbs).any()  # a treasure beside the start is found faster along the circle


def test_the_climb_reads_the_map_and_pays():
    treasure = np.array([np.cos(2.0), np.sin(2.0)])
    env = suite.load("mountain_treasure_sparse", seed=0, treasure=treasure)
    rewards, positions, _ = run(env, _Strategy(scripted.MountainClimber()))
    # Ten steps up (the map is read strictly within 0.1 of the top), then the walk to the treasure.
    first_top = int(np.argmax(np.linalg.norm(positions, axis=1) < 0.1)) + 1
    assert first_top == 10
    at_treasure = np.linalg.norm(positions - treasure, axis=1) <= 0.1
    first_treasure = int(np.argmax(at_treasure)) + 1
    assert at_treasure[first_treasure - 1 :].all()  # stays on the treasure
    expected = sum(reference_reward(p, treasure) for p in positions)
    assert rewards.sum() == pytest.approx(expected)
    assert rewards.sum() > 700  # ≈ 80 steps on the treasure at +10 outweigh the climb
    metrics = mt.treasure_metrics({"position": positions[:, None]}, rewards[:, None], treasure[None])
    assert metrics["reached_top"][0] == 1 and metrics["first_top_step"][0] == 10
    assert metrics["treasure_reached"][0] == 1
    assert metrics["steps_to_treasure_after_top"][0] == first_treasure - first_top
    assert mt.reads_the_map({k: float(v[0]) for k, v in metrics.items()})
    # Walking the circle without climbing finds it too, later, and never reads the map.
    circling = suite.load("mountain_treasure_sparse", seed=0, treasure=treasure)

    def circle(t, obs):
        p = obs["position"]
        radial = p / np.linalg.norm(p) * (1.0 - np.linalg.norm(p))
        return np.clip(np.array([-p[1], p[0]]) + 5 * radial, -1, 1)  # counter-clockwise on the circle

    r_circle, p_circle, _ = run(circling, circle)
    m_circle = mt.treasure_metrics({"position": p_circle[:, None]}, r_circle[:, None], treasure[None])
    assert m_circle["reached_top"][0] == 0 and np.isnan(m_circle["steps_to_treasure_after_top"][0])
    assert m_circle["treasure_reached"][0] == 1
    assert not mt.reads_the_map({k: float(v[0]) for k, v in m_circle.items()})
    assert r_circle.sum() < rewards.sum()


def test_finite_prior_candidates_and_errors():
    prior = mt.TreasurePrior(num_goals=8)
    support = prior.support()
    np.testing.assert_allclose(np.linalg.norm(support, axis=1), 1.0)
    np.testing.assert_allclose(np.arctan2(support[:, 1], support[:, 0]) % (2 * np.pi), np.arange(8) * np.pi / 4)
    rng = np.random.default_rng(0)
    draws = np.array([prior.sample(rng) for _ in range(400)])
    assert {tuple(np.round(d, 9)) for d in draws} == {tuple(np.round(s, 9)) for s in support}
    angles = np.array([np.arctan2(*mt.TreasurePrior().sample(rng)[::-1]) for _ in range(2000)])
    assert (angles < -np.pi / 2).any() and (angles > np.pi / 2).any()  # the whole circle, not a half
    with pytest.raises(ValueError, match="not one of the prior's 8 candidates"):
        suite.load(K8, seed=0, treasure=[0.5, 0.5])
    with pytest.raises(ValueError, match="num_goals must be a positive integer"):
        mt.TreasurePrior(num_goals=0)


def test_exact_belief_rules_out_visited_candidates_and_reads_the_map():
    support = mt.TreasurePrior(num_goals=8).support()
    true = 3  # at 135°
    env = suite.load(K8, seed=0, privileged=True, treasure=support[true])
    ts = env.reset()
    np.testing.assert_allclose(ts.observation["belief"], np.full(8, 1 / 8))
    # Walk to candidate 7 (315°), then back to candidate 6 (270°: the start, which the first step leaves).
    for target, ruled_out in ((7, {7}), (6, {6, 7})):
        for _ in range(40):
            p = ts.observation["position"]
            if np.linalg.norm(p - support[target]) < 0.05:
                break
            step = (support[target] - p) / 0.1
            ts = env.step(step / max(1.0, np.abs(step).max()))
        belief = ts.observation["belief"]
        assert set(np.flatnonzero(belief == 0)) >= ruled_out
        np.testing.assert_allclose(belief[belief > 0], 1 / np.count_nonzero(belief))
    # Then up to the top: the map leaves only the true candidate.
    for _ in range(40):
        if np.linalg.norm(ts.observation["position"]) < 0.1:
            break
        step = -ts.observation["position"] / 0.1
        ts = env.step(step / max(1.0, np.abs(step).max()))
    one_hot = np.zeros(8)
    one_hot[true] = 1.0
    np.testing.assert_array_equal(ts.observation["belief"], one_hot)
    np.testing.assert_array_equal(ts.observation["treasure_map"], support[true])


def test_top_down_behaviour_plot(tmp_path):
    view = suite.top_down(K8)
    assert view is not None and view.key == "position" and view.extent == (-1.5, 1.5, -1.5, 1.5)
    assert suite.top_down("cheetah_dir_sparse") is None
    env = suite.load(K8, seed=0)
    runs = [run(env, _Strategy(scripted.MountainClimber())) for _ in range(3)]
    tasks = np.array([env.task.task_parameters])
    data = {
        "obs_position": np.stack([r[1] for r in runs[:1]], axis=1),
        "rewards": np.stack([r[0] for r in runs[:1]], axis=1),
        "tasks": tasks,
    }
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = report._top_down_plot(data, {"agent": "scripted", "task": K8, "seed": 0}, view, tmp_path / "b.png", plt)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 5000
    with pytest.raises(ValueError, match="extent"):
        suite.TopDownView("position", (1.0, -1.0, 0.0, 1.0))
