"""The agent users make: a deployable `Policy` that can also `train` (through a `Trainer`).

    agent = agents.make("hyperx")
    agent.train("cheetah_dir_sparse", frames=1_000_000, seed=0, checkpoint_dir="runs/x")
    action, state = agent.act(obs)

Deployment (`act`, `save`, `load`, ...) is `agents/policy.py`; the training loop, its `TrainState`
(the checkpoint) and eq. (4) are `agents/trainer.py`; the typed rollout is `agents/rollout.py`.
"""

from __future__ import annotations

import os
from collections.abc import Callable

from hyperstate.agents.beliefs import belief_class
from hyperstate.agents.policy import AgentState, Policy
from hyperstate.agents.trainer import Trainer, bonus_anneal_factor, combine_rewards

__all__ = ["Agent", "AgentState", "bonus_anneal_factor", "combine_rewards"]


class Agent(Policy):
    """A meta-RL agent assembled from a config; see `agents.make`. It follows the benchmarkable-agent
    protocol of `hyperstate.evaluation` (train, act, save, load, belief_features, reads_true_task)."""

    @property
    def reads_true_task(self) -> bool:
        """Whether the policy is conditioned on the true task (the task-aware reference); known from the
        config's belief component, so before training too."""
        return bool(belief_class(self.config.belief).reads_true_task)

    def train(
        self,
        task: str,
        frames: int,
        seed: int = 0,
        *,
        task_kwargs: dict | None = None,
        checkpoint_dir: str | os.PathLike | None = None,
        resume: bool = False,
        progress: bool = True,
        on_iteration: Callable[[dict], None] | None = None,
        on_rollout: Callable[[dict], None] | None = None,
        stop_after_iterations: int | None = None,
    ) -> list[dict]:
        """Trains for `frames` environment steps on `task`; returns the per-iteration log.

        `on_iteration(log)` is called after every iteration (`log["frames"]`: environment steps so far);
        if it returns True, a checkpoint is written right then (the harness asks at its evaluation points,
        so a resumed run rejoins its learning curve). `on_rollout(arrays)` gets the rollout's raw
        observations ((T, N, ...) arrays per key, overwritten by the next rollout), for metrics such as
        visitation. `stop_after_iterations` stops early (the run can later `resume`); checkpoints go to
        `checkpoint_dir/checkpoint.pt` every `checkpoint_every` iterations and at the end, and
        `resume=True` continues from there exactly (a checkpoint of another run is refused).
        """
        trainer = Trainer(self, task, frames, seed, task_kwargs=task_kwargs, checkpoint_dir=checkpoint_dir)
        self.total_frames = trainer.state.frames
        return trainer.run(
            resume=resume,
            progress=progress,
            on_iteration=on_iteration,
            on_rollout=on_rollout,
            stop_after_iterations=stop_after_iterations,
        )
