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


@pytest.fixture
def slider_task():
    @suite.register("test_slider_goal_sparse")
    def slider_goal(seed=None, episodes_per_task=2, episode_length=40, privileged=False):
        physics = mujoco.Physics.from_xml_string(SLIDER_XML)
        task = SparseSliderGoal(
            GoalPrior(),
            episode_length=episode_length,
            episodes_per_task=episodes_per_task,
            privileged=privileged,
            random=seed,
        )
        return control.Environment(physics, task)

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
        "point_robot_sparse": "point_robot",
    }
    for sparse, dense in pairs.items():
        a, b = suite.load(sparse, seed=0, privileged=True), suite.load(dense, seed=0, privileged=True)
        assert a.observation_spec() == b.observation_spec() and a.action_spec() == b.action_spec()
        assert type(suite.task_prior(sparse)) is type(suite.task_prior(dense))
    with pytest.raises(ValueError, match="reference_task must be another task's name"):
        suite.register("self_reference", reference_task="self_reference")
    suite.register("dangling_reference", reference_task="no_such_task")(lambda seed=None: None)
    try:
        with pytest.raises(ValueError, match="names reference_task 'no_such_task', which is not registered"):
            suite.reference_task("dangling_reference")
    finally:
        suite.unregister("dangling_reference")


def test_spawn_seeds_are_reproducible():
    a, b = suite.spawn_seeds(5, 3), suite.spawn_seeds(5, 3)
    assert [s.generate_state(2).tolist() for s in a] == [s.generate_state(2).tolist() for s in b]
    assert len({tuple(s.generate_state(2)) for s in a}) == 3
    gen = suite.as_generator(np.random.SeedSequence(5))
    assert [s.generate_state(1)[0] for s in suite.spawn_seeds(gen, 3)] == [s.generate_state(1)[0] for s in a]
