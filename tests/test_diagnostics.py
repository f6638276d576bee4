"""Diagnostics of the turn-around: the bonus landscape (Figure 1), stochastic deployment, reward-stream
shares, and the Bayes bracket drawn only where it brackets."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from hyperstate import agents, suite
from hyperstate.agents.bonuses import BonusInput
from hyperstate.evaluation import diagnostics
from hyperstate.evaluation.cell import CellSpec, run_cell
from hyperstate.evaluation.deploy import deploy, evaluation_tasks
from hyperstate.evaluation.report import bayes_bracket

TINY = {"ppo.num_envs": 4, "ppo.rollout_length": 50, "ppo.minibatches": 1}
TASK = "cheetah_dir_sparse"


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    out = tmp_path_factory.mktemp("grid")
    spec = CellSpec("oracle_rh", TASK, 0, 600, 200, 2, None, TINY, str(out), False, False)
    return out, spec, run_cell(spec)


def test_cell_records_stochastic_returns_reward_shares_advantage_spreads_and_turn_metrics(cell):
    out, _, record = cell
    assert len(record["curve"]) == 3
    (events,) = (out / "tb").glob("*/events.out.tfevents.*")
    logged = EventAccumulator(str(events), size_guidance={"scalars": 0})
    logged.Reload()
    spreads = [(e.step, e.value) for e in logged.Scalars("advantage_std/combined")]
    previous = 0
    for point in record["curve"]:
        assert isinstance(point["online_return_stochastic"], float)
        shares = point["reward_share"]
        assert set(shares) == {"extrinsic", "0_rnd_hyperstate"}
        assert sum(shares.values()) == pytest.approx(1.0) and all(0 <= v <= 1 for v in shares.values())
        # One value head (no intrinsic_gamma): the combined stream's advantage spread, averaged since the last point.
        assert set(point["advantage_std"]) == {"combined"} and point["advantage_std"]["combined"] > 0
        since = [value for step, value in spreads if previous < step <= point["frames"]]
        assert since and point["advantage_std"]["combined"] == pytest.approx(np.mean(since), rel=1e-6)
        previous = point["frames"]
    final = record["final"]
    assert final["stochastic"]["online_return"] == pytest.approx(record["curve"][-1]["online_return_stochastic"])
    for name in ("wrong_first_exit", "turned_around", "return_forward", "return_backward", "return_wrong_first"):
        assert name in final["exploration_metric_names"]
    # Per-direction returns average to the online return (one forward, one backward held-out task).
    assert np.mean([final["return_forward"], final["return_backward"]]) == pytest.approx(final["online_return"])


def test_stochastic_deployment_is_seeded_and_leaves_the_callers_rng_alone(cell):
    out, spec, _ = cell
    agent = agents.Agent.load(spec.directory / "agent.pt")
    tasks = evaluation_tasks(TASK, 2)
    torch.manual_seed(123)
    before = torch.get_rng_state()
    first = deploy(agent, TASK, tasks, deterministic=False)
    again = deploy(agent, TASK, tasks, deterministic=False)
    assert torch.equal(torch.get_rng_state(), before)
    np.testing.assert_array_equal(first.rewards, again.rewards)
    mean_policy = deploy(agent, TASK, tasks)
    assert not np.array_equal(first.rewards, mean_policy.rewards)


def test_bonus_value_is_the_reward_without_learning(cell):
    _, spec, _ = cell
    agent = agents.Agent.load(spec.directory / "agent.pt")
    (bonus,) = agent.bonuses
    obs = suite.batch(TASK, 5, seed=3, privileged=True).reset().observation
    obs["x_displacement"] = np.linspace(-8, 8, 5)[:, None]
    features = np.tile([0.0, 1.0], (5, 1))
    stats = bonus.input_stats.state_dict()
    values = agent.bonus_values(obs, features)["0_rnd_hyperstate"]
    after = bonus.input_stats.state_dict()
    assert all(np.array_equal(np.asarray(stats[k]), np.asarray(after[k])) for k in stats)  # learned nothing
    # With statistics that one more batch cannot move, the training reward is the same function.
    bonus.input_stats.count = 1e15
    state = torch.as_tensor(agent.state_vector(obs), dtype=torch.float32)
    feats = torch.as_tensor(features, dtype=torch.float32)
    full = BonusInput(state, torch.zeros(5, 6), torch.zeros(5, 1), state, feats, feats)
    np.testing.assert_allclose(bonus.reward(full).numpy(), values, rtol=1e-5)


def test_landscape_is_the_bonus_at_each_position_and_belief(cell):
    _, spec, _ = cell
    agent = agents.Agent.load(spec.directory / "agent.pt")
    template = suite.batch(TASK, 1, seed=0, privileged=True).reset().observation
    xs = np.array([-12.0, -3.0, 0.5, 7.0])
    features = np.array([[0.5, 0.5], [1.0, 0.0], [0.0, 1.0]])
    grid = diagnostics.landscape(agent, template, "x_displacement", xs, features)["0_rnd_hyperstate"]
    assert grid.shape == (3, 4)
    for v, f in enumerate(features):
        for j, x in enumerate(xs):
            obs = {k: np.asarray(a).copy() for k, a in template.items()}
            obs["x_displacement"] = np.array([[x]])
            (one,) = agent.bonus_values(obs, f[None])["0_rnd_hyperstate"]
            assert grid[v, j] == pytest.approx(float(one), rel=1e-5)
    assert not np.allclose(grid[1], grid[2])  # the belief is part of the input


def test_state_bonus_landscape_ignores_the_belief():
    agent = agents.make("oracle_rs", **TINY)
    agent.train(TASK, frames=200, seed=0, progress=False)
    template = suite.batch(TASK, 1, seed=0, privileged=True).reset().observation
    grid = diagnostics.landscape(
        agent, template, "x_displacement", np.linspace(-9, 9, 7), np.array([[0.5, 0.5], [1.0, 0.0]])
    )["0_rnd_state"]
    np.testing.assert_array_equal(grid[0], grid[1])
    assert grid[0].std() > 0


def test_cell_diagnostics_draws_the_landscape_through_training(cell):
    out, spec, _ = cell
    path = diagnostics.cell_diagnostics(out, spec.cell_id)
    assert path == out / "figures" / f"bonus_{spec.cell_id}.png" and path.stat().st_size > 10_000
    data = np.load(spec.directory / "bonus_landscape.npz")
    np.testing.assert_array_equal(data["frames"], [200, 400, 600])
    assert data["training_0_rnd_hyperstate"].shape == (3, 3, diagnostics.GRID_POINTS)  # checkpoints × beliefs × x
    assert list(data["belief_labels"]) == ["prior", "end of task [-1.0]", "end of task [1.0]"]
    assert data["deployment_0_rnd_hyperstate"].shape == (2, 200, diagnostics.GRID_POINTS)
    assert data["deployment_x"].shape == (200, 2)
    # A preset without an evaluable bonus gets no landscape.
    plain = CellSpec("oracle", TASK, 0, 200, 200, 2, None, TINY, str(out), False, False)
    run_cell(plain)
    assert diagnostics.cell_diagnostics(out, plain.cell_id) is None


def test_bayes_bracket_draws_only_bounds():
    both = bayes_bracket({"bayes_estimate": 600.0, "adaptive_reference_return": 420.0})
    assert [(v, s) for v, _, s in both] == [(600.0, "--"), (420.0, ":")]
    # An upper estimate below an achieved Bayes-adaptive return is no bound: left out, and said so.
    inverted = bayes_bracket({"bayes_estimate": 198.0, "adaptive_reference_return": 225.0})
    assert [(v, s) for v, _, s in inverted] == [(225.0, ":")]
    assert "198 not drawn" in inverted[0][1]
    assert bayes_bracket({"bayes_estimate": None, "adaptive_reference_return": None}) == []
    assert [v for v, _, _ in bayes_bracket({"bayes_estimate": 5.0, "adaptive_reference_return": None})] == [5.0]
