"""Training: a `Trainer` runs the loop over one `TrainState`, whose `state_dict` is the checkpoint.

One iteration: collect a `Rollout` from `suite.batch` (the policy on normalised state ⊕ belief features,
the belief updated with every transition), compute every bonus over the whole rollout in one batch,
combine rewards by eq. (4) — extrinsic and each bonus divided by the std of its own running discounted
return, bonuses weighted by λ and annealed on their schedules — then the PPO, bonus and belief updates.
The `TrainState` holds everything (networks, optimiser, statistics, simulator state, the unfinished
BAMDP episode, RNGs), so a run resumed from its checkpoint continues exactly where it stopped.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from hyperstate import suite
from hyperstate.agents import config as config_lib
from hyperstate.agents import serialization
from hyperstate.agents.beliefs import Transition
from hyperstate.agents.bonuses import BonusInput
from hyperstate.agents.normalization import ReturnScaler
from hyperstate.agents.policy import Policy
from hyperstate.agents.ppo import gaussian_log_prob, ppo_update
from hyperstate.agents.rewards import bonus_anneal_factor, combine_rewards, intrinsic_discount  # noqa: F401
from hyperstate.agents.rollout import Rollout
from hyperstate.agents.train_state import Carry, PhaseClock, TrainState, TrajectoryBuffer  # noqa: F401


class Trainer:
    """Trains a `Policy` on a task: builds its `TrainState`, runs the iterations, checkpoints."""

    def __init__(
        self,
        policy: Policy,
        task: str,
        frames: int,
        seed: int = 0,
        *,
        task_kwargs: dict | None = None,
        checkpoint_dir: str | os.PathLike | None = None,
    ):
        if frames <= 0:
            raise ValueError(f"frames must be positive, got {frames}")
        cfg, p = policy.config, policy.config.ppo
        config_lib.check_budget(cfg, frames)
        torch.set_num_threads(cfg.torch_threads)
        # A runtime choice: parallel cells of a grid share the cores through $HYPERSTATE_PHYSICS_THREADS.
        threads = cfg.physics_threads or int(os.environ.get("HYPERSTATE_PHYSICS_THREADS", "0"))
        env = suite.batch(task, p.num_envs, seed=seed, num_threads=threads, privileged=True, **(task_kwargs or {}))
        policy.build(env.observation_spec(), env.action_spec(), seed, suite.position_keys(task))
        self.policy = policy
        self.iterations = math.ceil(frames / (p.num_envs * p.rollout_length))
        # Bonus annealing counts its progress over the budget, or over `bonus_anneal_frames` when set.
        anneal_frames = frames if cfg.bonus_anneal_frames is None else cfg.bonus_anneal_frames
        self.anneal_iterations = math.ceil(anneal_frames / (p.num_envs * p.rollout_length))
        optimizer = torch.optim.Adam(
            [*policy.model.parameters(), *policy.belief.policy_parameters()], lr=p.lr, eps=1e-5
        )
        first = env.reset()
        carry = Carry(
            obs=first.observation,
            belief=policy.belief.initial_state(p.num_envs, policy.tensors(first.observation)),
            is_start=np.ones(p.num_envs, bool),
            episode_return=np.zeros(p.num_envs),
        )
        self.state = TrainState(
            task=task,
            seed=seed,
            frames=self.iterations * p.num_envs * p.rollout_length,
            policy=policy,
            optimizer=optimizer,
            env=env,
            carry=carry,
            ext_scaler=ReturnScaler(p.num_envs, p.gamma),
            bonus_scalers=[ReturnScaler(p.num_envs, intrinsic_discount(p)) for _ in policy.bonuses],
            trajectories=TrajectoryBuffer(cfg.vae.buffer_trajectories),
        )
        self.rollout = Rollout.allocate(
            p.rollout_length,
            p.num_envs,
            policy.state_dim,
            policy.belief.feature_dim,
            policy.action_dim,
            policy.obs_spec,
            value_heads=cfg.value_heads,
        )
        self.checkpoint = Path(checkpoint_dir) / "checkpoint.pt" if checkpoint_dir else None
        self.clock = PhaseClock()

    # The loop --------------------------------------------------------------------------------------
    def run(
        self,
        *,
        resume: bool = False,
        progress: bool = True,
        on_iteration: Callable[[dict], None] | None = None,
        on_rollout: Callable[[dict], None] | None = None,
        stop_after_iterations: int | None = None,
    ) -> list[dict]:
        """Runs the remaining iterations; returns the per-iteration log (see `Agent.train`)."""
        state, p = self.state, self.policy.config.ppo
        if resume and self.checkpoint is not None and self.checkpoint.exists():
            self.restore(self.checkpoint)
        start_iteration = state.iteration
        elapsed = state.history[-1]["wall_seconds"] if state.history else 0.0
        bar = tqdm(
            total=self.iterations,
            initial=start_iteration,
            disable=not progress,
            desc=f"{self.policy.name} on {state.task}",
            unit="it",
            dynamic_ncols=True,
        )
        started = time.perf_counter() - elapsed
        frames_per_iteration = p.num_envs * p.rollout_length
        lr_iterations = self.iterations  # the learning rate reaches 0 after this many iterations
        if p.lr_anneal_frames is not None:
            lr_iterations = math.ceil(p.lr_anneal_frames / frames_per_iteration)
        for iteration in range(start_iteration, self.iterations):
            if p.anneal_lr:
                for group in state.optimizer.param_groups:
                    group["lr"] = p.lr * max(0.0, 1.0 - iteration / lr_iterations)
            t0 = time.perf_counter()
            returns = self.collect()
            collect_seconds = time.perf_counter() - t0
            if on_rollout is not None:
                on_rollout(self.rollout.raw_obs)
            log = self.learn(iteration)
            log.update(self.clock.lap())
            log.update(
                iteration=iteration + 1,
                frames=(iteration + 1) * frames_per_iteration,
                wall_seconds=time.perf_counter() - started,
                fps=frames_per_iteration / (time.perf_counter() - t0),
                collect_fps=frames_per_iteration / collect_seconds,
                train_return=float(np.mean(returns)) if returns else None,
            )
            state.history.append(log)
            state.iteration = iteration + 1
            asked = on_iteration(log) is True if on_iteration is not None else False
            bar.update(1)
            if log["train_return"] is not None:
                bar.set_postfix(ret=f"{log['train_return']:.1f}", fps=f"{log['fps']:.0f}")
            done = state.iteration == self.iterations
            stopping = stop_after_iterations is not None and state.iteration - start_iteration >= stop_after_iterations
            every = self.policy.config.checkpoint_every
            if self.checkpoint is not None and (
                (every > 0 and state.iteration % every == 0) or done or stopping or asked
            ):
                self.save_checkpoint(self.checkpoint)
            if stopping:
                break
        bar.close()
        state.env.close()
        return state.history

    # Checkpoints -------------------------------------------------------------------------------------
    def save_checkpoint(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        serialization.save(self.state.state_dict(), path, kind="checkpoint")  # atomic: a crash keeps the last one

    def restore(self, path: Path) -> None:
        saved = serialization.load(path, kind="checkpoint")
        # The config as this code reads it: a checkpoint from before a config field existed holds its default.
        saved_config = config_lib.to_dict(config_lib.from_dict(config_lib.AgentConfig, saved["config"]))
        config, task, seed, frames = self.state.identity()
        if (config_lib.agent_settings(saved_config), saved["task"], saved["seed"]) != (
            config_lib.agent_settings(config),
            task,
            seed,
        ) or saved["frames"] > frames:
            raise ValueError(f"checkpoint {path} was written by a different run (config, task, seed or frames)")
        if saved["frames"] < frames:  # extending a finished or shorter run: only if its schedules allow it
            reason = config_lib.budget_dependence(self.policy.config)
            if reason is not None:
                raise ValueError(
                    f"checkpoint {path} was trained for a budget of {saved['frames']:,} frames; continuing it to "
                    f"{frames:,} would change its schedule ({reason})"
                )
        self.state.load_state_dict(saved)

    # Collection ----------------------------------------------------------------------------------------
    def collect(self) -> list[float]:
        """Fills `self.rollout` with `rollout_length` steps of every env; returns the extrinsic returns of
        the BAMDP episodes that ended during it."""
        policy, state, r = self.policy, self.state, self.rollout
        p = policy.config.ppo
        carry = state.carry
        obs, bstate, is_start, episode_return = carry.obs, carry.belief, carry.is_start, carry.episode_return
        r.belief_state0 = bstate
        completed: list[float] = []
        clock = self.clock
        clock.start()
        with torch.inference_mode():
            for t in range(p.rollout_length):
                raw = policy.state_vector(obs)
                if p.norm_obs:
                    policy.obs_stats.update(raw)
                normalized = policy.normalized(raw)
                features = policy.belief.features(bstate)
                mean, std, value = policy.model.step(normalized, features)
                noise = torch.randn(mean.shape, generator=policy.generator)
                action = mean + std * noise
                clock.mark("inference")
                out = state.env.step(action.numpy().astype(np.float64))
                clock.mark("physics")
                final = out.final_observation
                next_raw = policy.state_vector(final)
                reward = torch.as_tensor(out.reward, dtype=torch.float32)[:, None]
                transition = Transition(
                    action, reward, torch.as_tensor(next_raw, dtype=torch.float32), policy.tensors(final)
                )
                bnext = policy.belief.update(bstate, transition)
                next_features = policy.belief.features(bnext)
                last = out.last
                r.next_values[t] = 0.0
                if last.any():
                    r.next_values[t] = policy.model.value(policy.normalized(next_raw), next_features)
                    bnext = policy.belief.reset_where(bnext, torch.as_tensor(last), policy.tensors(out.observation))
                clock.mark("belief")
                episode_return = episode_return + out.reward
                completed.extend(episode_return[last].tolist())
                episode_return = np.where(last, 0.0, episode_return)
                r.store_step(
                    t,
                    obs=obs,
                    state=torch.as_tensor(raw, dtype=torch.float32),
                    policy_state=normalized,
                    next_state=transition.next_state,
                    features=features,
                    next_features=next_features,
                    action=action,
                    logprob=gaussian_log_prob(noise, std),
                    value=value,
                    reward=reward[:, 0],
                    last=torch.as_tensor(last, dtype=torch.float32),
                    bootstrap=torch.as_tensor(out.discount, dtype=torch.float32),
                    start=torch.as_tensor(is_start),
                )
                obs, bstate, is_start = out.observation, bnext, last
                clock.mark("rollout")
            final_value = policy.model.value(
                policy.normalized(policy.state_vector(obs)), policy.belief.features(bstate)
            )
            r.bootstrap_from(final_value)
        clock.mark("inference")
        state.carry = Carry(obs, bstate, is_start, episode_return)
        return completed

    # Learning ------------------------------------------------------------------------------------------
    def learn(self, iteration: int) -> dict:
        """The algorithm on the collected rollout: intrinsic rewards → eq. (4) → advantages → PPO → belief
        training; returns the iteration's log."""
        policy, rollout, p = self.policy, self.rollout, self.policy.config.ppo
        log: dict[str, Any] = {"reward/extrinsic_mean": float(rollout.rewards.numpy().astype(np.float64).mean())}
        self.clock.start()
        extrinsic = self.training_reward()
        raw_bonuses = self.intrinsic_rewards(log)
        reward, intrinsic = self.combine(extrinsic, raw_bonuses, iteration, log)
        log.update(rollout.compute_returns_and_advantages(self.reward_streams(reward, intrinsic), p.gae_lambda))
        self.clock.mark("returns")  # eq. (4) and GAE
        log.update(ppo_update(policy.model, policy.belief, self.state.optimizer, rollout, p, policy.generator))
        self.clock.mark("ppo")
        log.update(self.train_belief())
        self.clock.mark("belief_training")
        return log

    def training_reward(self) -> np.ndarray:
        """The extrinsic reward PPO trains on, (T, N): the task's, minus the sampled-action cost. Stores the
        rollout's whole trajectories for belief training first, so that bonuses trained on replayed
        trajectories see this rollout's too."""
        rollout, p = self.rollout, self.policy.config.ppo
        extrinsic = rollout.rewards.numpy().astype(np.float64)
        if self.policy.belief.trainable:
            self.store_trajectories(rollout.lasts.numpy().astype(bool))
        self.clock.mark("belief_training")
        if p.sampled_action_cost > 0:
            extrinsic = extrinsic - p.sampled_action_cost * self.excess_action_energy(rollout.actions.numpy())
        return extrinsic

    def intrinsic_rewards(self, log: dict) -> list[np.ndarray]:
        """Each bonus's raw reward on the rollout, (T, N) each; then each bonus trains on it (its losses go
        to `log`)."""
        policy, rollout = self.policy, self.rollout
        t_len, n = rollout.shape
        raw_bonuses = []
        if policy.bonuses:
            flat = BonusInput(
                state=rollout.state.reshape(t_len * n, -1),
                action=rollout.actions.reshape(t_len * n, -1),
                reward=rollout.rewards.reshape(t_len * n, 1),
                next_state=rollout.next_state.reshape(t_len * n, -1),
                features=rollout.features.reshape(t_len * n, -1),
                next_features=rollout.next_features.reshape(t_len * n, -1),
                replay=self.replayed_inputs if policy.belief.trainable else None,
            )
            for bonus in policy.bonuses:
                raw_bonuses.append(bonus.reward(flat).numpy().astype(np.float64).reshape(t_len, n))
                log.update(bonus.update(flat))
        self.clock.mark("bonus")  # the bonuses' rewards and their networks' updates
        return raw_bonuses

    def combine(
        self, extrinsic: np.ndarray, raw_bonuses: list[np.ndarray], iteration: int, log: dict
    ) -> tuple[np.ndarray, np.ndarray]:
        """Eq. (4): the reward PPO sees and its intrinsic part, (T, N) each; each stream's share goes to `log`."""
        policy, state, cfg = self.policy, self.state, self.policy.config
        p = cfg.ppo
        progress = iteration / self.anneal_iterations
        anneals = [bonus_anneal_factor(b, cfg.anneal_bonus, progress) for b in cfg.bonuses]
        reward, scaled_bonuses = combine_rewards(
            extrinsic,
            raw_bonuses,
            weights=[b.weight for b in cfg.bonuses],
            anneal=anneals,
            bonus_clips=[b.clip for b in cfg.bonuses],
            lasts=self.rollout.lasts.numpy().astype(bool),
            ext_scaler=state.ext_scaler if p.norm_reward else None,
            bonus_scalers=state.bonus_scalers,
            reward_clip=p.reward_clip,
        )
        weighted = []  # (name, the bonus as eq. (4) added it to the reward)
        for bonus, config, factor, raw, scaled in zip(
            policy.bonuses, cfg.bonuses, anneals, raw_bonuses, scaled_bonuses, strict=True
        ):
            log[f"bonus/{bonus.name}/raw_mean"] = float(raw.mean())
            log[f"bonus/{bonus.name}/scaled_mean"] = float(scaled.mean())
            weighted.append((bonus.name, factor * config.weight * scaled))
        intrinsic = sum((w for _, w in weighted), np.zeros_like(reward))
        if weighted:
            # Each stream's share of the reward PPO sees (mean magnitude after normalisation and weighting).
            magnitude = {"extrinsic": float(np.abs(reward - intrinsic).mean())}
            magnitude.update({name: float(np.abs(w).mean()) for name, w in weighted})
            total = sum(magnitude.values()) or 1.0
            log.update({f"reward_share/{name}": m / total for name, m in magnitude.items()})
        return reward, intrinsic

    def reward_streams(self, reward: np.ndarray, intrinsic: np.ndarray) -> list[tuple[str, np.ndarray, float]]:
        """One reward stream per value head: the combined reward, or (two heads: `ppo.intrinsic_gamma`) the
        extrinsic and the intrinsic parts, each with its own discount."""
        p = self.policy.config.ppo
        if self.policy.config.value_heads == 2:
            return [("extrinsic", reward - intrinsic, p.gamma), ("intrinsic", intrinsic, p.intrinsic_gamma)]
        return [("combined", reward, p.gamma)]

    def train_belief(self) -> dict:
        """`vae.updates_per_iteration` steps of the belief's own loss on stored trajectories; their mean losses."""
        policy, state, vae = self.policy, self.state, self.policy.config.vae
        if not policy.belief.trainable or not state.trajectories.items:
            return {}
        losses = [
            policy.belief.train_step(state.trajectories.sample(vae.batch_trajectories, policy.generator))
            for _ in range(vae.updates_per_iteration)
        ]
        return {k: float(np.mean([x[k] for x in losses])) for k in losses[0]}

    def replayed_inputs(self, n: int) -> BonusInput | None:
        """About `n` transitions from the stored whole trajectories, the belief recomputed by its current model
        (`BonusInput.replay`): ⌊√n⌋ steps, drawn with replacement, of each of n // ⌊√n⌋ trajectories, as the
        reference code draws its RND's inputs from the VAE's buffer. None while no trajectory is stored."""
        if not self.state.trajectories.items:
            return None
        per_trajectory = max(1, math.isqrt(n))
        count = max(1, n // per_trajectory)
        generator = self.policy.generator
        trajectories = self.state.trajectories.sample(count, generator)
        features = self.policy.belief.replay_features(trajectories)  # (B, T+1, F): b_0 … b_T
        steps = torch.randint(trajectories.actions.shape[1], (count, per_trajectory), generator=generator)
        rows = torch.arange(count)[:, None]

        def pick(x: torch.Tensor, offset: int = 0) -> torch.Tensor:
            return x[rows, steps + offset].reshape(count * per_trajectory, -1)

        return BonusInput(
            state=pick(trajectories.states),
            action=pick(trajectories.actions),
            reward=pick(trajectories.rewards),
            next_state=pick(trajectories.states, 1),
            features=pick(features),
            next_features=pick(features, 1),
        )

    def excess_action_energy(self, actions: np.ndarray) -> np.ndarray:
        """|a|² − |clip(a)|² per step of sampled (T, N, A) actions: what a control cost on the sampled action
        charges beyond the task's cost on the clipped one."""
        a = actions.astype(np.float64)
        clipped = np.clip(a, *self.policy.action_bounds)
        return np.sum(np.square(a), axis=-1) - np.sum(np.square(clipped), axis=-1)

    def store_trajectories(self, lasts: np.ndarray) -> None:
        """Cuts the rollout at BAMDP episode ends (synchronous across envs) into whole trajectories."""
        if not (lasts.all(axis=1) | ~lasts.any(axis=1)).all():
            raise RuntimeError("BAMDP episodes must end on the same step in every env")
        rollout, state = self.rollout, self.state
        pieces = {
            "state": rollout.state.numpy(),
            "next_state": rollout.next_state.numpy(),
            "actions": rollout.actions.numpy(),
            "rewards": rollout.rewards.numpy(),
        }
        tasks = rollout.tasks
        start = 0
        chunks = state.episode_chunks
        for t in np.flatnonzero(lasts[:, 0]):
            chunks.append({k: v[start : t + 1] for k, v in pieces.items()})
            whole = {k: np.concatenate([c[k] for c in chunks]) for k in pieces}
            states = np.concatenate([whole["state"], whole["next_state"][-1:]])
            state.trajectories.add(
                states, whole["actions"], whole["rewards"], None if tasks is None else tasks[t].copy()
            )
            chunks.clear()
            start = t + 1
        if start < lasts.shape[0]:
            # Copies: the rollout's buffers are overwritten by the next collection.
            chunks.append({k: v[start:].copy() for k, v in pieces.items()})
