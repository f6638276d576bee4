"""The Gymnasium adapter."""

import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from dm_control.rl import control
from dm_control.suite import reacher
from gymnasium.utils.env_checker import check_env

from hyperstate import suite
from hyperstate.suite import gym as suite_gym


@pytest.mark.parametrize(
    "name,size",
    [
        ("cheetah_dir_sparse", 8 + 9 + 1 + 1),
        ("cheetah_vel_sparse", 8 + 9 + 1 + 1),
        ("point_robot_sparse", 2 + 2 + 1),
        ("point_treasure_sparse", 2 + 2 + 1),
        ("quadruped_goal_sparse", 44 + 3 + 1 + 6 + 24 + 2 + 2 + 1),  # dm_control's + position, heading
    ],
)
def test_passes_gymnasium_env_checker(name, size):
    env = suite_gym.make(name, episode_length=20)
    check_env(env, skip_render_check=True)
    assert env.observation_space.shape == (size,)


def test_registry_ids_seeding_truncation_and_privileged_info():
    env = gymnasium.make("hyperstate/cheetah_dir_sparse", episode_length=5, episodes_per_task=2)
    obs, info = env.reset(seed=3)
    again, info_again = env.reset(seed=3)
    np.testing.assert_array_equal(obs, again)
    np.testing.assert_array_equal(info["task"], info_again["task"])
    np.testing.assert_array_equal(info["belief"], [0.5, 0.5])
    # Matches the dm_control environment observation for observation.
    dm = suite.load("cheetah_dir_sparse", seed=3, episode_length=5, episodes_per_task=2)
    first = dm.reset().observation
    want = np.concatenate([first[k].ravel() for k in ("position", "velocity", "x_displacement", "inner_episode")])
    np.testing.assert_allclose(obs, want.astype(np.float32))
    flags = []
    for _ in range(10):
        obs, reward, terminated, truncated, info = env.step(np.zeros(6, np.float32))
        dm_step = dm.step(np.zeros(6))
        assert reward == pytest.approx(dm_step.reward)
        flags.append((terminated, truncated))
    assert flags[-1] == (False, True) and all(f == (False, False) for f in flags[:-1])


def test_stable_baselines3_ppo_trains_on_it():
    from stable_baselines3 import PPO

    env = suite_gym.make("cheetah_dir", episode_length=50)
    model = PPO("MlpPolicy", env, n_steps=256, batch_size=64, n_epochs=1, seed=0, device="cpu", verbose=0)
    model.learn(total_timesteps=1024)
    action, _ = model.predict(env.reset(seed=0)[0], deterministic=True)
    assert env.action_space.contains(action)


class _SparseReacher(reacher.Reacher):
    """A user's task in dm_control's own style: seeded with `random=seed`, drawing its target and initial
    joint angles from dm_control's RandomState; reward 1 only inside the target."""

    def get_reward(self, physics):
        radii = physics.named.model.geom_size[["target", "finger"], 0].sum()
        return float(physics.finger_to_target_dist() <= radii)


@pytest.fixture
def dm_style_task():
    @suite.register("test_sparse_reacher_dm_style")
    def sparse_reacher(seed=None, privileged=False):
        physics = reacher.Physics.from_xml_string(*reacher.get_model_and_assets())
        return control.Environment(physics, _SparseReacher(target_size=0.015, random=seed), time_limit=1.0)

    yield "test_sparse_reacher_dm_style"
    suite.unregister("test_sparse_reacher_dm_style")


def test_reset_with_a_seed_is_deterministic_for_a_dm_control_style_task(dm_style_task):
    env = suite_gym.make(dm_style_task)
    check_env(env, skip_render_check=True)  # includes Gymnasium's determinism check
    first, _ = env.reset(seed=7)
    steps = [env.step(env.action_space.sample())[0] for _ in range(3)]
    other, _ = env.reset(seed=8)
    again, _ = env.reset(seed=7)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)  # the seed reaches dm_control's RandomState
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(3)]
    env.reset(seed=7)
    replay = [env.step(a)[0] for a in actions]
    env.reset(seed=7)
    np.testing.assert_array_equal(replay, [env.step(a)[0] for a in actions])
    assert len(steps) == 3


def test_gymnasium_make_works_from_a_fresh_interpreter():
    """The README's one-liner, in a process that imported nothing of hyperstate before."""
    code = (
        "import gymnasium, numpy as np\n"
        "env = gymnasium.make('hyperstate.suite.gym:hyperstate/cheetah_dir_sparse', episodes_per_task=2)\n"
        "obs, info = env.reset(seed=0)\n"
        "print(obs.shape[0], info['belief'].tolist())\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["19", "[0.5,", "0.5]"]  # position 8, velocity 9, x, inner episode
