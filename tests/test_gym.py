"""The Gymnasium adapter."""

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import suite
import suite.gym


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
    env = suite.gym.make(name, episode_length=20)
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

    env = suite.gym.make("cheetah_dir", episode_length=50)
    model = PPO("MlpPolicy", env, n_steps=256, batch_size=64, n_epochs=1, seed=0, device="cpu", verbose=0)
    model.learn(total_timesteps=1024)
    action, _ = model.predict(env.reset(seed=0)[0], deterministic=True)
    assert env.action_space.contains(action)
