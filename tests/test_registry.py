"""The public registry, exercised the way a user would: a new sparse meta-task defined in this file."""

import collections

import numpy as np
import pytest
from dm_control import mujoco
from dm_control.rl import control

from hyperstate import suite
from hyperstate.suite.base import MetaTask, check_action

SLIDER_XML = """
<mujoco>
  <option timestep="0.02"/>
  <worldbody>
    <body name="cart"><joint name="slider" type="slide" axis="1 0 0" damping="1"/>
      <geom type="box" size=".1 .1 .1" mass="1"/></body>
  </worldbody>
  <actuator><motor joint="slider" gear="10" ctrllimited="true" ctrlrange="-1 1"/></actuator>
</mujoco>
"""


class GoalPrior:
    """Goal at -1 or +1 on a line."""

    def sample(self, rng):
        return np.array([rng.choice([-1.0, 1.0])])

    def support(self):
        return np.array([[-1.0], [1.0]])


class SparseSliderGoal(MetaTask):
    """Reward 1 within 0.2 of the goal, else 0; the belief collapses when a goal spot is visited."""

    def prior_belief(self):
        return np.array([0.5, 0.5])

    def initialize_mdp_episode(self, physics):
        physics.data.qpos[:] = 0.0

    def before_step(self, action, physics):
        physics.set_control(check_action(action, self.action_spec(physics)))

    def transition_reward(self, physics):
        x = float(physics.data.qpos[0])
        for _i, goal in enumerate(self.prior.support()[:, 0]):
            if abs(x - goal) < 0.2:  # visiting either spot tells where the goal is
                self._belief = np.eye(2)[int(self._task[0] > 0)]
                return float(goal == self._task[0])
        return 0.0

    def mdp_observation(self, physics):
        return collections.OrderedDict(position=physics.data.qpos.copy(), velocity=physics.data.qvel.copy())


def slider_goal(seed=None, episodes_per_task=2, episode_length=40, privileged=False):
    """The slider task's factory, registered by the fixtures below."""
    physics = mujoco.Physics.from_xml_string(SLIDER_XML)
    task = SparseSliderGoal(
        GoalPrior(),
        episode_length=episode_length,
        episodes_per_task=episodes_per_task,
        privileged=privileged,
        random=seed,
    )
    return control.Environment(physics, task)


@pytest.fixture
def slider_task():
    suite.register("test_slider_goal_sparse")(slider_goal)
    yield "test_slider_goal_sparse"
    suite.unregister("test_slider_goal_sparse")


def test_user_task_registers_loads_and_batches(slider_task):
    assert slider_task in suite.TASKS and slider_task in suite.list_tasks()
    env = suite.load(slider_task, seed=0, privileged=True)
    step = env.reset()
    goal = step.observation["task"][0]
    rewards, t = [], 0
    while not step.last():
        step = env.step(np.array([goal]))  # push toward the goal
        rewards.append(step.reward)
        t += 1
    assert t == 80 and max(rewards) == 1.0
    np.testing.assert_array_equal(env.task.belief, np.eye(2)[int(goal > 0)])
    # Tasks without a fast batch are batched by LoopBatch, auto-resetting like the fast ones.
    vec = suite.batch(slider_task, 3, seed=0, privileged=True)
    assert isinstance(vec, suite.LoopBatch)
    first = vec.reset()
    assert first.observation["position"].shape == (3, 1)
    lasts = [vec.step(np.sign(first.observation["task"])).last.copy() for _ in range(80)]
    assert [i for i, x in enumerate(lasts) if x.any()] == [79] and lasts[79].all()


def test_unknown_task_lists_registered_names():
    with pytest.raises(ValueError, match=r"unknown task 'cheetah_sparse'.*cheetah_dir, cheetah_dir_sparse"):
        suite.load("cheetah_sparse")
    with pytest.raises(ValueError, match="unknown task"):
        suite.batch("nope", 2)


def test_unknown_kwarg_is_named(slider_task):
    with pytest.raises(TypeError, match=r"'goal_radius'.*accepted: episodes_per_task, episode_length, privileged"):
        suite.load(slider_task, goal_radius=0.3)
    with pytest.raises(TypeError, match="'zone'"):
        suite.load("cheetah_dir_sparse", zone=3)


def test_duplicate_and_malformed_registrations(slider_task):
    with pytest.raises(ValueError, match="already registered"):
        suite.register(slider_task)(lambda seed=None: None)
    with pytest.raises(TypeError, match="seed"):
        suite.register("no_seed_task")(lambda: None)
    assert "no_seed_task" not in suite.TASKS


def test_reference_tasks_are_dense_counterparts_with_the_same_interface():
    pairs = {t: suite.reference_task(t) for t in suite.TASKS if suite.reference_task(t)}
    assert pairs == {
        "cheetah_dir_sparse": "cheetah_dir",
        "cheetah_vel_sparse": "cheetah_vel",
        "point_robot_sparse": "point_robot_3ep",
        "mountain_treasure_sparse": "mountain_treasure",
        "mountain_treasure_k8_sparse": "mountain_treasure_k8",
    }
    for sparse, dense in pairs.items():
        a, b = suite.load(sparse, seed=0, privileged=True), suite.load(dense, seed=0, privileged=True)
        assert a.observation_spec() == b.observation_spec() and a.action_spec() == b.action_spec()
        assert type(suite.task_prior(sparse)) is type(suite.task_prior(dense))
        horizon = lambda env: (env.task.episodes_per_task, env.task.episode_length)  # noqa: E731
        assert horizon(a) == horizon(b)
    with pytest.raises(ValueError, match="reference_task must be another task's name"):
        suite.register("self_reference", reference_task="self_reference")
    suite.register("dangling_reference", reference_task="no_such_task")(lambda seed=None: None)
    try:
        with pytest.raises(ValueError, match="names reference_task 'no_such_task', which is not registered"):
            suite.reference_task("dangling_reference")
    finally:
        suite.unregister("dangling_reference")


def test_a_reference_task_over_another_horizon_is_refused():
    """The dense `point_robot` has 1 MDP episode per task: a task-aware reference trained there never sees
    `inner_episode` 1 or 2 and is lost in the sparse task's later episodes, so it cannot be the reference."""
    from hyperstate.suite import point_robot

    def three_episodes(seed=None, **kwargs):
        return suite.load("point_robot_sparse", seed=seed, **kwargs)

    suite.register("three_episodes_one_episode_reference", reference_task="point_robot")(three_episodes)
    try:
        with pytest.raises(ValueError) as refused:
            suite.reference_task("three_episodes_one_episode_reference")
        message = str(refused.value)
        assert f"has {point_robot.SPARSE_EPISODES} MDP episode(s) of {point_robot.EPISODE_LENGTH} steps" in message
        assert f"'point_robot' has 1 MDP episode(s) of {point_robot.EPISODE_LENGTH} steps" in message
    finally:
        suite.unregister("three_episodes_one_episode_reference")


def test_spawn_seeds_are_reproducible():
    a, b = suite.spawn_seeds(5, 3), suite.spawn_seeds(5, 3)
    assert [s.generate_state(2).tolist() for s in a] == [s.generate_state(2).tolist() for s in b]
    assert len({tuple(s.generate_state(2)) for s in a}) == 3
    gen = suite.as_generator(np.random.SeedSequence(5))
    assert [s.generate_state(1)[0] for s in suite.spawn_seeds(gen, 3)] == [s.generate_state(1)[0] for s in a]


# What the evaluation harness knows of a task, it learns from the task's declarations -------------------
SLIDER_AXIS = suite.PositionAxis("position", "cart position (m)", symbol="x", unit="m", region=(-0.5, 0.5))


@pytest.fixture
def declared_slider(slider_task):
    """The slider again, declaring a position axis, a coverage grid and a Bayes-optimal estimator."""
    factory = slider_goal
    suite.register(
        "test_slider_declared",
        position_axis=SLIDER_AXIS,
        coverage=suite.Coverage("position", low=-1.0, high=1.0, bins=4, belief_bins=2),
        bayes_estimate=lambda returns: float(np.mean(returns)) - 1.0,
    )(factory)
    yield "test_slider_declared"
    suite.unregister("test_slider_declared")


def _records(task):
    def record(agent, seed, per_task):
        return {
            "agent": agent,
            "task": task,
            "seed": seed,
            "curve": [],
            "final": {"online_return": float(np.mean(per_task)), "online_return_per_task": per_task},
        }

    return [record("task_aware", 0, [4.0, 6.0]), record("mine", 0, [1.0, 2.0])]


def test_a_task_gets_coverage_plots_captions_and_bayes_estimate_only_by_declaring_them(
    slider_task, declared_slider, tmp_path
):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hyperstate.evaluation import grid, report
    from hyperstate.evaluation.coverage import HyperStateCoverage

    # Coverage: the declared grid, cells computed from the declared observation.
    assert HyperStateCoverage.for_task(slider_task) is None
    coverage = HyperStateCoverage.for_task(declared_slider)
    coverage.update({"position": np.array([[[-0.9]], [[0.9]], [[5.0]]]), "belief": np.full((3, 1, 2), 0.5)})
    assert coverage.visited.tolist() == [[False, True], [False, False], [False, False], [False, True]]
    # Bayes-optimal estimate: the declared function of the reference's returns per deployment.
    rows = {(r["task"], r["agent"]): r for r in report.summary_rows(_records(slider_task) + _records(declared_slider))}
    assert rows[(declared_slider, "mine")]["bayes_estimate"] == pytest.approx(4.0)
    assert rows[(declared_slider, "mine")]["gap_to_bayes"] == pytest.approx(2.5)
    assert rows[(slider_task, "mine")]["bayes_estimate"] is None
    # Behaviour plot: drawn along the declared axis from the saved deployment, none without an axis.
    figures = tmp_path / "figures"
    figures.mkdir()
    for task in (slider_task, declared_slider):
        record = {"agent": "mine", "task": task, "seed": 0}
        directory = grid.cell_dir(tmp_path, grid.record_cell_id(record))
        directory.mkdir(parents=True)
        positions = np.linspace(0, 1, 80).reshape(40, 2, 1)
        np.savez(directory / grid.DEPLOYMENT, obs_position=positions, tasks=np.array([[-1.0], [1.0]]))
        drawn = report._behaviour_plot(tmp_path, record, figures, plt)
        assert (drawn is not None) == (task == declared_slider)
    # Captions: the declared axis in words, its region named.
    assert SLIDER_AXIS.describe(0.2) == "x +0.2 m (inside region)"
    assert SLIDER_AXIS.describe(-0.5) == "x -0.5 m (outside region)"
    with pytest.raises(ValueError, match="low < high"):
        suite.PositionAxis("position", "p", region=(1.0, -1.0))
    with pytest.raises(TypeError, match="suite.Coverage"):
        suite.register("bad_coverage", coverage=("position", 0, 1))(lambda seed=None: None)


def _words_in_code(source: str, words: set[str]) -> list[str]:
    """Identifiers and strings of `source` (docstrings aside) that contain one of `words`."""
    import ast

    tree = ast.parse(source)
    docstrings = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant):
            text = node.value if id(node) not in docstrings else None
        elif isinstance(node, ast.FunctionDef | ast.ClassDef):
            text = node.name
        else:
            text = getattr(node, "id", None) or getattr(node, "attr", None) or getattr(node, "arg", None)
        if isinstance(text, str) and any(word in text.lower() for word in words):
            found.append(f"{node.lineno}: {text[:60]!r}")
    return found


def test_the_evaluation_harness_names_no_task():
    """No identifier or string in evaluation/'s code (docstrings aside: they may show a command line)
    names a built-in task, its observations or its attributes: the harness reads declarations only."""
    from pathlib import Path

    import hyperstate.evaluation as evaluation

    banned = {*suite.TASKS, "cheetah", "point_robot", "quadruped", "x_displacement", "zone_radius", "bayes_optimal"}
    found = {
        path.name: hits
        for path in sorted(Path(evaluation.__file__).parent.glob("*.py"))
        if (hits := _words_in_code(path.read_text(), banned))
    }
    assert not found, found
    # The scan finds what it looks for, in code, and not in a docstring.
    source = '"""Runs cheetah_dir."""\ndef run(zone_radius):\n    return load(f"{x}_cheetah", x_displacement)\n'
    assert sorted(_words_in_code(source, banned)) == ["2: 'zone_radius'", "3: '_cheetah'", "3: 'x_displacement'"]
