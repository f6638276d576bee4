"""The training loop's pieces: the typed rollout, collection into it, and the TrainState that is the checkpoint."""

from __future__ import annotations

import numpy as np
import torch

from hyperstate import agents
from hyperstate.agents import serialization
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
