"""The training loop's pieces: the typed rollout, collection into it, and the TrainState that is the checkpoint."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from hyperstate import agents
from hyperstate.agents import serialization
from hyperstate.agents import trainer as trainer_module
from hyperstate.agents.rollout import Rollout
from hyperstate.agents.trainer import Trainer

TINY = {"ppo.num_envs": 3, "ppo.rollout_length": 30, "vae.batch_trajectories": 2}
TASK_KWARGS = {"episode_length": 20, "episodes_per_task": 2}  # BAMDP episodes of 40 steps: they span rollouts


def _trainer(preset: str = "hyperx", **overrides) -> Trainer:
    return Trainer(
        agents.make(preset, **TINY, **overrides), "cheetah_dir_sparse", frames=900, seed=2, task_kwargs=TASK_KWARGS
    )


def test_rollout_buffers_are_typed_and_preallocated():
    rollout = Rollout.allocate(5, 4, 19, 10, 6, {"x": ((1,), "float64"), "task": ((1,), "float64")})
    assert rollout.shape == (5, 4)
    assert rollout.state.shape == (5, 4, 19) and rollout.features.shape == (5, 4, 10)
    assert rollout.actions.shape == (5, 4, 6) and rollout.starts.dtype == torch.bool
    assert rollout.raw_obs["x"].shape == (5, 4, 1) and rollout.tasks is rollout.raw_obs["task"]


def test_collection_fills_the_rollout_in_place_consistently():
    trainer = _trainer()
    rollout = trainer.rollout
    buffers = {name: getattr(rollout, name).data_ptr() for name in ("state", "actions", "values", "next_values")}
    trainer.collect()
    trainer.collect()  # the second rollout: episodes started in the first one end here
    assert {name: getattr(rollout, name).data_ptr() for name in buffers} == buffers  # filled in place
    policy = trainer.policy
    x_column = policy.key_columns["x_displacement"][0]
    x = rollout.raw_obs["x_displacement"][..., 0]
    np.testing.assert_array_equal(rollout.state[..., x_column].numpy(), x.astype(np.float32))
    lasts = rollout.lasts.bool()
    assert lasts[9].all() and lasts.sum() == 3  # step 40 of the run is step 10 of this rollout
    assert rollout.starts[10].all() and not rollout.starts[11].any()
    # Within an episode, V(s_{t+1}) is the next step's V(s_t); at its end, the final observation's value.
    np.testing.assert_array_equal(rollout.next_values[:9].numpy(), rollout.values[1:10].numpy())
    assert (rollout.bootstrap == 1.0).all()  # truncations only: the BAMDP horizon is no termination


def test_unfinished_episode_pieces_do_not_alias_the_rollout():
    trainer = _trainer()
    trainer.collect()
    trainer.learn(0)  # stores the first 30 steps of the unfinished 40-step episodes
    (piece,) = trainer.state.episode_chunks
    kept = piece["state"].copy()
    assert not np.shares_memory(piece["state"], trainer.rollout.state.numpy())
    trainer.collect()  # overwrites the rollout
    np.testing.assert_array_equal(piece["state"], kept)
    trainer.learn(1)
    assert len(trainer.state.trajectories.items) == 3 and trainer.state.trajectories.items[0][0].shape == (41, 19)


def test_train_state_is_the_checkpoint(tmp_path):
    trainer = _trainer("oracle_rh")
    trainer.run(progress=False, stop_after_iterations=2)
    trainer.save_checkpoint(tmp_path / "checkpoint.pt")
    fresh = _trainer("oracle_rh")
    fresh.restore(tmp_path / "checkpoint.pt")
    assert fresh.state.iteration == 2 and len(fresh.state.history) == 2

    def encoded(state) -> bytes:
        saved = serialization.encode(state.state_dict())
        saved.pop("history")  # wall-clock times
        return repr(saved).encode()

    assert encoded(fresh.state) == encoded(trainer.state)


def _gae_calls(monkeypatch) -> tuple[list, list]:
    """Spies on the trainer's eq. (4) and GAE calls: (combined rewards, [(stream, gamma, advantages, returns)])."""
    from hyperstate.agents import rollout as rollout_module
    from hyperstate.agents import trainer as trainer_module

    combined, gae = [], []
    real_combine, real_gae = trainer_module.combine_rewards, rollout_module.compute_gae

    def combine(*args, **kwargs):
        out = real_combine(*args, **kwargs)
        combined.append((out[0].copy(), [b.copy() for b in out[1]]))
        return out

    def compute(rewards, values, next_values, lasts, bootstrap, gamma, lam):
        adv, ret = real_gae(rewards, values, next_values, lasts, bootstrap, gamma, lam)
        gae.append((rewards.copy(), gamma, adv, ret))
        return adv, ret

    monkeypatch.setattr(trainer_module, "combine_rewards", combine)
    monkeypatch.setattr(rollout_module, "compute_gae", compute)
    return combined, gae


def test_one_value_head_learns_the_combined_reward(monkeypatch):
    combined, gae = _gae_calls(monkeypatch)
    trainer = _trainer("hyperx")
    assert trainer.rollout.values.shape == (30, 3, 1)
    trainer.collect()
    log = trainer.learn(0)
    ((reward, _),) = combined
    ((stream, gamma, adv, ret),) = gae
    assert gamma == 0.97 and np.array_equal(stream, reward)
    assert log["advantage_std/combined"] == pytest.approx(adv.std(), rel=1e-12)
    np.testing.assert_array_equal(trainer.rollout.advantages.numpy(), adv.astype(np.float32))
    np.testing.assert_array_equal(trainer.rollout.returns[..., 0].numpy(), ret.astype(np.float32))


def test_intrinsic_value_head_splits_the_reward_into_two_discounted_streams(monkeypatch):
    combined, gae = _gae_calls(monkeypatch)
    trainer = _trainer("hyperx", **{"ppo.intrinsic_gamma": 0.995})
    policy = trainer.policy
    assert [s.gamma for s in trainer.state.bonus_scalers] == [0.995, 0.995]  # bonuses normalised under γ_i
    assert trainer.state.ext_scaler.gamma == 0.97
    features = torch.zeros(4, policy.belief.feature_dim)
    assert policy.model.value(torch.zeros(4, policy.state_dim), features).shape == (4, 2)
    trainer.collect()
    log = trainer.learn(0)
    ((reward, scaled),) = combined
    (ext, ext_gamma, ext_adv, ext_ret), (intrinsic, int_gamma, int_adv, int_ret) = gae
    assert (ext_gamma, int_gamma) == (0.97, 0.995)
    weights = [b.weight for b in policy.config.bonuses]
    np.testing.assert_allclose(intrinsic, weights[0] * scaled[0] + weights[1] * scaled[1], rtol=1e-12)
    np.testing.assert_allclose(ext + intrinsic, reward, rtol=1e-12, atol=1e-12)
    # Each stream's advantage spread is logged under its name (what steers PPO after normalisation).
    assert log["advantage_std/extrinsic"] == pytest.approx(ext_adv.std(), rel=1e-12)
    assert log["advantage_std/intrinsic"] == pytest.approx(int_adv.std(), rel=1e-12)
    assert "advantage_std/combined" not in log
    assert np.abs(intrinsic).mean() > 0.1 and np.abs(ext).mean() > 0  # both streams carry reward
    rollout = trainer.rollout
    np.testing.assert_allclose(rollout.advantages.numpy(), ext_adv + int_adv, rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(rollout.returns[..., 0].numpy(), ext_ret.astype(np.float32))
    np.testing.assert_array_equal(rollout.returns[..., 1].numpy(), int_ret.astype(np.float32))
    # The intrinsic head's GAE uses its own discount: recompute its last step by hand.
    t, values, next_values = 29, rollout.values[..., 1].numpy(), rollout.next_values[..., 1].numpy()
    np.testing.assert_allclose(int_adv[t], intrinsic[t] + 0.995 * next_values[t] - values[t], rtol=1e-6, atol=1e-6)


def test_intrinsic_value_head_config_errors():
    import pytest

    with pytest.raises(ValueError, match="intrinsic_gamma"):
        agents.make("oracle_rh", **{"ppo.intrinsic_gamma": 1.0})
    # Without bonuses there is nothing to split: one head (so a config's [all] table may set it for every
    # agent, the task-aware reference included).
    assert agents.make("oracle", **{"ppo.intrinsic_gamma": 0.99}).config.value_heads == 1


def test_a_checkpoint_from_before_a_config_field_resumes(tmp_path):
    trainer = _trainer("oracle_rh")
    trainer.run(progress=False, stop_after_iterations=1)
    trainer.save_checkpoint(tmp_path / "checkpoint.pt")
    saved = serialization.load(tmp_path / "checkpoint.pt", kind="checkpoint")
    del saved["config"]["ppo"]["intrinsic_gamma"]  # as written before the field existed
    serialization.save(saved, tmp_path / "checkpoint.pt", kind="checkpoint")
    fresh = _trainer("oracle_rh")
    fresh.restore(tmp_path / "checkpoint.pt")
    assert fresh.state.iteration == 1


def test_a_learning_rate_horizon_beyond_the_budget_trains_as_the_longer_runs_first_frames():
    """`ppo.lr_anneal_frames`: a 3-iteration run whose rate decays over 9 iterations' frames is, weight for
    weight, the first 3 iterations of a 9-iteration run; the rates it used are 1, 8/9 and 7/9 of `lr`."""
    kwargs = dict(task_kwargs=TASK_KWARGS, seed=2)
    per_iteration = TINY["ppo.num_envs"] * TINY["ppo.rollout_length"]
    short = Trainer(agents.make("hyperx", **TINY, **{"ppo.lr_anneal_frames": 9 * per_iteration}),
                    "cheetah_dir_sparse", frames=3 * per_iteration, **kwargs)  # fmt: skip
    rates = []
    short.run(progress=False, on_iteration=lambda log: rates.append(short.state.optimizer.param_groups[0]["lr"]))
    lr = short.policy.config.ppo.lr
    assert rates == pytest.approx([lr, lr * 8 / 9, lr * 7 / 9], rel=1e-12)
    budget_horizon = {"ppo.lr_anneal_frames": None}  # over its own 9 iterations
    long = Trainer(agents.make("hyperx", **TINY, **budget_horizon), "cheetah_dir_sparse", frames=9 * per_iteration,
                   **kwargs)  # fmt: skip
    long.run(progress=False, stop_after_iterations=3)
    for (name, a), (_, b) in zip(
        short.policy.model.state_dict().items(), long.policy.model.state_dict().items(), strict=True
    ):
        assert torch.equal(a, b), name
    # The budget's own horizon (None) decays to 0 at its end: the 3-iteration run would differ.
    default = Trainer(agents.make("hyperx", **TINY, **budget_horizon), "cheetah_dir_sparse",
                      frames=3 * per_iteration, **kwargs)  # fmt: skip
    default.run(progress=False)
    assert not torch.equal(default.policy.model.actor["body"][-1].weight, long.policy.model.actor["body"][-1].weight)
    with pytest.raises(ValueError, match="lr_anneal_frames"):
        agents.make("hyperx", **{"ppo.lr_anneal_frames": 0})


def test_a_bonus_annealing_horizon_beyond_the_budget_trains_as_the_longer_runs_first_frames(monkeypatch):
    """`bonus_anneal_frames` (with `ppo.lr_anneal_frames`): an annealed preset's 3-iteration run on a
    9-iteration schedule is, weight for weight, the first 3 iterations of a 9-iteration run, and its bonus
    weights were 1, 8/9 and 7/9 of λ; on its own budget's schedule (the default) it would differ."""
    kwargs = dict(task_kwargs=TASK_KWARGS, seed=1)
    per_iteration = TINY["ppo.num_envs"] * TINY["ppo.rollout_length"]
    small = {**TINY, "bonuses.0.buffer_size": 1000}  # the preset's 1e7-input buffer is not what is tested
    horizon = {"ppo.lr_anneal_frames": 9 * per_iteration, "bonus_anneal_frames": 9 * per_iteration}
    short = Trainer(agents.make("oracle_rh_icml", **small, **horizon), "cheetah_dir_sparse", frames=3 * per_iteration,
                    **kwargs)  # fmt: skip
    factors = []
    original = trainer_module.bonus_anneal_factor

    def spy(bonus, anneal_all, progress):
        factors.append(original(bonus, anneal_all, progress))
        return factors[-1]

    monkeypatch.setattr(trainer_module, "bonus_anneal_factor", spy)
    short.run(progress=False)
    monkeypatch.undo()
    assert factors == pytest.approx([1.0, 8 / 9, 7 / 9], rel=1e-12)
    long = Trainer(agents.make("oracle_rh_icml", **small), "cheetah_dir_sparse", frames=9 * per_iteration, **kwargs)
    long.run(progress=False, stop_after_iterations=3)
    for (name, a), (_, b) in zip(
        short.policy.model.state_dict().items(), long.policy.model.state_dict().items(), strict=True
    ):
        assert torch.equal(a, b), name
    lr_only = Trainer(agents.make("oracle_rh_icml", **small, **{"ppo.lr_anneal_frames": 9 * per_iteration}),
                      "cheetah_dir_sparse", frames=3 * per_iteration, **kwargs)  # fmt: skip
    lr_only.run(progress=False)
    assert not torch.equal(lr_only.policy.model.actor["body"][-1].weight, long.policy.model.actor["body"][-1].weight)
    with pytest.raises(ValueError, match="bonus_anneal_frames"):
        agents.make("oracle_rh_icml", **{"bonus_anneal_frames": -1})
