"""The agent: PPO + one belief + weighted bonuses, trained on a batched meta-task.

The training loop (`Agent.train`) is: collect a rollout from `suite.batch` (policy on normalised
state ⊕ belief features, belief updated with every transition), compute every bonus for the whole
rollout in one batch, combine rewards by eq. (4) — extrinsic and each bonus divided by the std of its
own running discounted return, bonuses weighted by λ and optionally annealed — then PPO, bonus and
belief updates. Checkpoints hold everything (networks, optimisers, statistics, simulator state, RNGs),
so `resume=True` continues exactly where an interrupted run stopped.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from hyperstate import suite
from hyperstate.agents import config as config_lib
from hyperstate.agents import serialization
from hyperstate.agents.beliefs import Trajectories, Transition, make_belief
from hyperstate.agents.bonuses import BonusInput, make_bonus
from hyperstate.agents.config import AgentConfig, BonusConfig
from hyperstate.agents.normalization import ReturnScaler, RunningMeanStd
from hyperstate.agents.ppo import ActorCritic, compute_gae, gaussian_log_prob, ppo_update

PRIVILEGED_KEYS = ("belief", "task")


@dataclasses.dataclass
class AgentState:
    """Deployment state of a batch of agents: belief state and the previous action."""

    belief: Any
    prev_action: torch.Tensor


def combine_rewards(
    extrinsic: np.ndarray,
    bonuses: list[np.ndarray],
    *,
    weights: list[float],
    anneal: float | Sequence[float],
    lasts: np.ndarray,
    ext_scaler: ReturnScaler | None,
    bonus_scalers: list[ReturnScaler],
    reward_clip: float,
    bonus_clips: Sequence[float | None] | None = None,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Eq. (4): r + Σ_i λ_i r_i, each stream divided by the std of its own running discounted return.

    The extrinsic stream is normalised and clipped to ±`reward_clip` (unless `ext_scaler` is None);
    each bonus is normalised, clipped to ±`bonus_clips[i]` where one is given, weighted, and multiplied by
    its annealing factor (`anneal`: one for all bonuses, or one per bonus; 1 − progress when annealing).
    Returns the combined (T, N) reward and the normalised (and clipped) bonuses.
    """
    anneals = [float(anneal)] * len(bonuses) if np.isscalar(anneal) else list(anneal)
    clips = list(bonus_clips) if bonus_clips is not None else [None] * len(bonuses)
    reward = extrinsic
    if ext_scaler is not None:
        reward = np.clip(ext_scaler.scale(extrinsic, lasts), -reward_clip, reward_clip)
    scaled = [scaler.scale(b, lasts) for b, scaler in zip(bonuses, bonus_scalers, strict=True)]
    scaled = [b if clip is None else np.clip(b, -clip, clip) for b, clip in zip(scaled, clips, strict=True)]
    for weight, factor, b in zip(weights, anneals, scaled, strict=True):
        reward = reward + factor * weight * b
    return reward, scaled


def bonus_anneal_factor(bonus: BonusConfig, anneal_all: bool, progress: float) -> float:
    """The weight multiplier of one bonus at `progress` (0 at the start of training, 1 at the end): linear
    to 0 at `bonus.anneal_until`, or over the whole run when the agent anneals every bonus; else 1."""
    until = bonus.anneal_until if bonus.anneal_until is not None else (1.0 if anneal_all else None)
    return 1.0 if until is None else max(0.0, 1.0 - progress / until)


class TrajectoryBuffer:
    """Whole BAMDP episodes for belief training (FIFO, `capacity` trajectories)."""

    def __init__(self, capacity: int):
        self.capacity = capacity
        self.items: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]] = []

    def add(self, states, actions, rewards, tasks) -> None:
        for i in range(states.shape[1]):
            self.items.append((states[:, i], actions[:, i], rewards[:, i], None if tasks is None else tasks[i]))
        del self.items[: max(0, len(self.items) - self.capacity)]

    def sample(self, n: int, generator: torch.Generator) -> Trajectories:
        idx = torch.randint(len(self.items), (n,), generator=generator).tolist()
        s, a, r, k = zip(*(self.items[i] for i in idx), strict=True)
        tasks = None if k[0] is None else torch.as_tensor(np.stack(k), dtype=torch.float32)
        return Trajectories(
            torch.as_tensor(np.stack(s), dtype=torch.float32),
            torch.as_tensor(np.stack(a), dtype=torch.float32),
            torch.as_tensor(np.stack(r), dtype=torch.float32)[..., None],
            tasks,
        )


class Agent:
    """A meta-RL agent assembled from a config; see `agents.make`."""

    def __init__(self, config: AgentConfig, name: str = "custom"):
        self.config = config
        self.name = name
        self._built = False

    # Construction ----------------------------------------------------------------------------------
    def _build(self, obs_spec: dict, action_spec, seed: int, position_keys: tuple[str, ...] | None = None) -> None:
        cfg = self.config
        self.position_keys = position_keys
        torch.manual_seed(seed)
        self.generator = torch.Generator().manual_seed(seed)
        public = [k for k in obs_spec if k not in PRIVILEGED_KEYS]
        self.state_keys = list(cfg.state_keys) if cfg.state_keys is not None else public
        for k in self.state_keys:
            if k not in obs_spec:
                raise ValueError(f"state key {k!r} is not an observation of this task; observations: {public}")
            if k in PRIVILEGED_KEYS:
                raise ValueError(f"{k!r} is privileged: only belief components may read it")
        sizes = [int(np.prod(obs_spec[k].shape)) for k in self.state_keys]
        offsets = np.cumsum([0, *sizes])
        self.key_columns = {k: list(range(offsets[i], offsets[i + 1])) for i, k in enumerate(self.state_keys)}
        self.state_dim = int(offsets[-1])
        self.action_dim = int(np.prod(action_spec.shape))
        self.obs_spec = {k: (tuple(v.shape), str(v.dtype)) for k, v in obs_spec.items()}
        self.action_bounds = (np.asarray(action_spec.minimum), np.asarray(action_spec.maximum))
        self.belief = make_belief(
            cfg.belief,
            state_dim=self.state_dim,
            action_dim=self.action_dim,
            obs_spec=obs_spec,
            vae=cfg.vae,
            recurrent=cfg.recurrent,
            generator=self.generator,
        )
        if cfg.ppo.minibatch_unit == "transitions" and self.belief.policy_parameters():
            raise ValueError(
                f"ppo.minibatch_unit 'transitions' needs a belief whose features are fixed in the rollout; the "
                f"{cfg.belief!r} belief is trained through time by the RL loss: use 'envs'"
            )
        self.model = ActorCritic(self.state_dim, self.belief.feature_dim, self.action_dim, cfg.ppo)
        self.optimizer = torch.optim.Adam(
            [*self.model.parameters(), *self.belief.policy_parameters()], lr=cfg.ppo.lr, eps=1e-5
        )
        self.bonuses = []
        for i, b in enumerate(cfg.bonuses):
            keys = b.state_keys if b.state_keys is not None else self.state_keys
            if keys == "task":
                if position_keys is None:
                    raise ValueError(
                        f"bonus {i} reads the task's position keys (state_keys='task'), but the task declares "
                        f"none; set bonuses.{i}.state_keys to some of {self.state_keys}"
                    )
                keys = position_keys
            missing = [k for k in keys if k not in self.key_columns]
            if missing:
                raise ValueError(f"bonus {i}: state keys {missing} are not state observations {self.state_keys}")
            columns = [c for k in keys for c in self.key_columns[k]]
            self.bonuses.append(
                make_bonus(b, state_columns=columns, belief=self.belief, generator=self.generator, index=i)
            )
        self.obs_stats = RunningMeanStd((self.state_dim,))
        self._built = True

    def _state_vector(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return np.concatenate(
            [np.asarray(obs[k], np.float64).reshape(len(obs[k]), -1) for k in self.state_keys], axis=-1
        )

    def _normalized(self, state: np.ndarray) -> torch.Tensor:
        x = self.obs_stats.normalize(state) if self.config.ppo.norm_obs else state
        return torch.as_tensor(x, dtype=torch.float32)

    @staticmethod
    def _tensors(obs: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
        # Beliefs read only the privileged keys from observations (the state comes separately).
        return {k: torch.as_tensor(np.asarray(obs[k]), dtype=torch.float32) for k in PRIVILEGED_KEYS if k in obs}

    # Deployment -------------------------------------------------------------------------------------
    def initial_state(self, obs: dict[str, np.ndarray]) -> AgentState:
        """The prior belief for a batch of first observations (the start of a BAMDP episode)."""
        t = self._tensors(obs)
        n = len(next(iter(obs.values())))
        return AgentState(self.belief.initial_state(n, t), torch.zeros(n, self.action_dim))

    def act(
        self,
        obs: dict[str, np.ndarray],
        state: AgentState | None = None,
        deterministic: bool = True,
        reward: np.ndarray | None = None,
    ) -> tuple[np.ndarray, AgentState]:
        """Action for a batch of observations (arrays with a leading batch axis).

        `state=None` starts a BAMDP episode from the prior belief; afterwards pass the returned state
        and the reward of the previous step so the belief can take in the transition.
        """
        if not self._built:
            raise RuntimeError("agent has no networks yet: train() or load() it first")
        with torch.no_grad():
            raw = self._state_vector(obs)
            if state is None:
                state = self.initial_state(obs)
            else:
                if reward is None:
                    raise ValueError("pass the previous step's reward with the state")
                transition = Transition(
                    state.prev_action,
                    torch.as_tensor(np.asarray(reward, np.float32).reshape(-1, 1)),
                    torch.as_tensor(raw, dtype=torch.float32),
                    self._tensors(obs),
                )
                state = AgentState(self.belief.update(state.belief, transition), state.prev_action)
            dist = self.model.distribution(self._normalized(raw), self.belief.features(state.belief))
            action = dist.mean if deterministic else dist.sample()
        return action.numpy().astype(np.float64), AgentState(state.belief, action)

    def belief_features(self, state: AgentState) -> np.ndarray:
        """The belief features of a deployment state (what the policy conditions on)."""
        return self.belief.features(state.belief).numpy()

    def bonus_values(self, obs: dict[str, np.ndarray], features: np.ndarray) -> dict[str, np.ndarray]:
        """What each bonus would pay for arriving at observations `obs` (a batch) with belief features
        `features` ((M, F)), learning nothing from it; only bonuses with a pure `value` (RND and its
        ensemble; not the VAE error, which needs a whole transition). For diagnostics such as the paper's
        Figure 1 (evaluation/diagnostics.py)."""
        if not self._built:
            raise RuntimeError("agent has no networks yet: train() or load() it first")
        next_state = torch.as_tensor(self._state_vector(obs), dtype=torch.float32)
        m = len(next_state)
        batch = BonusInput(
            state=next_state,
            action=torch.zeros(m, self.action_dim),
            reward=torch.zeros(m, 1),
            next_state=next_state,
            features=torch.as_tensor(features, dtype=torch.float32),
            next_features=torch.as_tensor(features, dtype=torch.float32),
        )
        return {b.name: b.value(batch).numpy() for b in self.bonuses if hasattr(b, "value")}

    # Training ---------------------------------------------------------------------------------------
    def check_task(self, task: str, task_kwargs: dict | None = None) -> None:
        """Raises ValueError (naming what is missing) if this agent cannot run on `task`, e.g. the
        oracle belief on a task without an exact belief; builds nothing that training keeps."""
        env = suite.load(task, seed=0, privileged=True, **(task_kwargs or {}))
        probe = Agent(self.config, self.name)
        probe._build(env.observation_spec(), env.action_spec(), 0, suite.position_keys(task))

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

        `on_iteration(log)` is called after every iteration; `on_rollout(arrays)` gets the rollout's raw
        observations ((T, N, ...) arrays per key), for metrics such as visitation.
        `stop_after_iterations` stops early (the run can later `resume`); checkpoints go to
        `checkpoint_dir/checkpoint.pt` every `checkpoint_every` iterations and at the end.
        """
        if frames <= 0:
            raise ValueError(f"frames must be positive, got {frames}")
        cfg, p = self.config, self.config.ppo
        torch.set_num_threads(cfg.torch_threads)
        env = suite.batch(
            task, p.num_envs, seed=seed, num_threads=cfg.physics_threads, privileged=True, **(task_kwargs or {})
        )
        self._build(env.observation_spec(), env.action_spec(), seed, suite.position_keys(task))
        n, t_len = p.num_envs, p.rollout_length
        iterations = math.ceil(frames / (n * t_len))
        self.total_frames = iterations * n * t_len
        ext_scaler = ReturnScaler(n, p.gamma)
        bonus_scalers = [ReturnScaler(n, p.gamma) for _ in self.bonuses]
        trainable_belief = self.config.belief in ("varibad", "task_supervised")
        self._episode_chunks: list[dict] = []  # the unfinished BAMDP episode, for the trajectory buffer
        buffer = TrajectoryBuffer(cfg.vae.buffer_trajectories)
        history: list[dict] = []
        ckpt = Path(checkpoint_dir) / "checkpoint.pt" if checkpoint_dir else None

        first = env.reset()
        carry = {
            "obs": first.observation,
            "belief": self.belief.initial_state(n, self._tensors(first.observation)),
            "is_start": np.ones(n, bool),
            "episode_return": np.zeros(n),
        }
        start_iteration, elapsed = 0, 0.0
        if resume and ckpt is not None and ckpt.exists():
            saved = serialization.load(ckpt, kind="checkpoint")
            same = (saved["config"], saved["task"], saved["seed"], saved["frames"]) == (
                config_lib.to_dict(cfg),
                task,
                seed,
                self.total_frames,
            )
            if not same:
                raise ValueError(f"checkpoint {ckpt} was written by a different run (config, task, seed or frames)")
            self._load_training_state(saved, env, ext_scaler, bonus_scalers, buffer)
            carry, history, start_iteration = saved["carry"], saved["history"], saved["iteration"]
            elapsed = history[-1]["wall_seconds"] if history else 0.0

        bar = tqdm(
            total=iterations,
            initial=start_iteration,
            disable=not progress,
            desc=f"{self.name} on {task}",
            unit="it",
            dynamic_ncols=True,
        )
        started = time.perf_counter() - elapsed
        for iteration in range(start_iteration, iterations):
            if p.anneal_lr:
                for group in self.optimizer.param_groups:
                    group["lr"] = p.lr * (1.0 - iteration / iterations)
            t0 = time.perf_counter()
            rollout, carry, returns = self._collect(env, carry)
            collect_seconds = time.perf_counter() - t0
            if on_rollout is not None:
                on_rollout(rollout["raw_obs"])
            log = self._learn(rollout, iteration, iterations, ext_scaler, bonus_scalers, buffer, trainable_belief)
            frames_done = (iteration + 1) * n * t_len
            log.update(
                iteration=iteration + 1,
                frames=frames_done,
                wall_seconds=time.perf_counter() - started,
                fps=n * t_len / (time.perf_counter() - t0),
                collect_fps=n * t_len / collect_seconds,
                train_return=float(np.mean(returns)) if returns else None,
            )
            history.append(log)
            if on_iteration is not None:
                on_iteration(log)
            bar.update(1)
            if log["train_return"] is not None:
                bar.set_postfix(ret=f"{log['train_return']:.1f}", fps=f"{log['fps']:.0f}")
            done = iteration + 1 == iterations
            stopping = stop_after_iterations is not None and iteration + 1 - start_iteration >= stop_after_iterations
            if ckpt is not None and ((iteration + 1) % cfg.checkpoint_every == 0 or done or stopping):
                self._save_training_state(
                    ckpt, task, seed, iteration + 1, env, carry, history, ext_scaler, bonus_scalers, buffer
                )
            if stopping:
                break
        bar.close()
        env.close()
        return history

    def _collect(self, env, carry: dict) -> tuple[dict, dict, list[float]]:
        """One rollout of `rollout_length` steps in every env."""
        p = self.config.ppo
        n, t_len = p.num_envs, p.rollout_length
        obs, bstate, is_start = carry["obs"], carry["belief"], carry["is_start"]
        episode_return = carry["episode_return"]
        keys = [
            "state",
            "policy_state",
            "next_state",
            "features",
            "next_features",
            "actions",
            "logprobs",
            "values",
            "next_values",
            "rewards",
            "lasts",
            "bootstrap",
            "starts",
        ]
        buf: dict[str, list] = {k: [] for k in keys}
        raw_obs: dict[str, list] = {k: [] for k in obs}
        tasks_seen = []
        belief_state0 = bstate
        completed = []
        with torch.inference_mode():
            for _ in range(t_len):
                raw = self._state_vector(obs)
                if p.norm_obs:
                    self.obs_stats.update(raw)
                state = self._normalized(raw)
                features = self.belief.features(bstate)
                mean, std = self.model.mean_std(state, features)
                noise = torch.randn(mean.shape, generator=self.generator)
                action = mean + std * noise
                value = self.model.value(state, features)
                out = env.step(action.numpy().astype(np.float64))
                final = out.final_observation
                next_raw = self._state_vector(final)
                reward = torch.as_tensor(out.reward, dtype=torch.float32)[:, None]
                transition = Transition(
                    action, reward, torch.as_tensor(next_raw, dtype=torch.float32), self._tensors(final)
                )
                bnext = self.belief.update(bstate, transition)
                next_features = self.belief.features(bnext)
                next_value = torch.zeros(n)
                last = out.last
                if last.any():
                    next_value = self.model.value(self._normalized(next_raw), next_features)
                    bnext = self.belief.reset_where(bnext, torch.as_tensor(last), self._tensors(out.observation))
                for k, v in obs.items():
                    raw_obs[k].append(v)
                tasks_seen.append(obs["task"] if "task" in obs else None)
                episode_return = episode_return + out.reward
                completed.extend(episode_return[last].tolist())
                episode_return = np.where(last, 0.0, episode_return)
                for k, v in (
                    ("state", torch.as_tensor(raw, dtype=torch.float32)),
                    ("policy_state", state),
                    ("next_state", transition.next_state),
                    ("features", features),
                    ("next_features", next_features),
                    ("actions", action),
                    ("logprobs", gaussian_log_prob(noise, std)),
                    ("values", value),
                    ("next_values", next_value),
                    ("rewards", reward[:, 0]),
                    ("lasts", torch.as_tensor(last, dtype=torch.float32)),
                    ("bootstrap", torch.as_tensor(out.discount, dtype=torch.float32)),
                    ("starts", torch.as_tensor(is_start)),
                ):
                    buf[k].append(v)
                obs, bstate, is_start = out.observation, bnext, last
            final_value = self.model.value(self._normalized(self._state_vector(obs)), self.belief.features(bstate))
        rollout = {k: torch.stack(v) for k, v in buf.items()}
        # V(s_{t+1}) for steps that did not end an episode is the next step's value.
        lasts = rollout["lasts"].bool()
        following = torch.cat([rollout["values"][1:], final_value[None]])
        rollout["next_values"] = torch.where(lasts, rollout["next_values"], following)
        rollout["bootstrap"] = torch.where(lasts, rollout["bootstrap"], torch.ones_like(rollout["bootstrap"]))
        rollout["belief_state0"] = belief_state0
        rollout["raw_obs"] = {k: np.stack(v) for k, v in raw_obs.items()}
        rollout["tasks"] = None if tasks_seen[0] is None else np.stack(tasks_seen)
        new_carry = {"obs": obs, "belief": bstate, "is_start": is_start, "episode_return": episode_return}
        return rollout, new_carry, completed

    def _learn(self, rollout, iteration, iterations, ext_scaler, bonus_scalers, buffer, trainable_belief) -> dict:
        p, cfg = self.config.ppo, self.config
        t_len, n = rollout["rewards"].shape
        lasts = rollout["lasts"].numpy().astype(bool)
        extrinsic = rollout["rewards"].numpy().astype(np.float64)
        log: dict[str, Any] = {"reward/extrinsic_mean": float(extrinsic.mean())}
        if p.sampled_action_cost > 0:
            extrinsic = extrinsic - p.sampled_action_cost * self._excess_action_energy(rollout["actions"].numpy())
        raw_bonuses = []
        if self.bonuses:
            flat = BonusInput(
                state=rollout["state"].reshape(t_len * n, -1),
                action=rollout["actions"].reshape(t_len * n, -1),
                reward=rollout["rewards"].reshape(t_len * n, 1),
                next_state=rollout["next_state"].reshape(t_len * n, -1),
                features=rollout["features"].reshape(t_len * n, -1),
                next_features=rollout["next_features"].reshape(t_len * n, -1),
            )
            for bonus in self.bonuses:
                raw_bonuses.append(bonus.reward(flat).numpy().astype(np.float64).reshape(t_len, n))
                log.update(bonus.update(flat))
        anneals = [bonus_anneal_factor(b, cfg.anneal_bonus, iteration / iterations) for b in cfg.bonuses]
        reward, scaled_bonuses = combine_rewards(
            extrinsic,
            raw_bonuses,
            weights=[b.weight for b in cfg.bonuses],
            anneal=anneals,
            bonus_clips=[b.clip for b in cfg.bonuses],
            lasts=lasts,
            ext_scaler=ext_scaler if p.norm_reward else None,
            bonus_scalers=bonus_scalers,
            reward_clip=p.reward_clip,
        )
        weighted = {}
        for bonus, config, factor, raw, scaled in zip(
            self.bonuses, cfg.bonuses, anneals, raw_bonuses, scaled_bonuses, strict=True
        ):
            log[f"bonus/{bonus.name}/raw_mean"] = float(raw.mean())
            log[f"bonus/{bonus.name}/scaled_mean"] = float(scaled.mean())
            weighted[bonus.name] = factor * config.weight * scaled
        if weighted:
            # Each stream's share of the reward PPO sees (mean magnitude after normalisation and weighting).
            magnitude = {"extrinsic": float(np.abs(reward - sum(weighted.values())).mean())}
            magnitude.update({name: float(np.abs(w).mean()) for name, w in weighted.items()})
            total = sum(magnitude.values()) or 1.0
            log.update({f"reward_share/{name}": m / total for name, m in magnitude.items()})
        advantages, returns = compute_gae(
            reward,
            rollout["values"].numpy(),
            rollout["next_values"].numpy(),
            lasts.astype(np.float64),
            rollout["bootstrap"].numpy(),
            p.gamma,
            p.gae_lambda,
        )
        rollout["advantages"] = torch.as_tensor(advantages, dtype=torch.float32)
        rollout["returns"] = torch.as_tensor(returns, dtype=torch.float32)
        log.update(ppo_update(self.model, self.belief, self.optimizer, rollout, p, self.generator))
        if trainable_belief:
            self._store_trajectories(rollout, lasts, buffer)
            if buffer.items:
                losses = [
                    self.belief.train_step(buffer.sample(cfg.vae.batch_trajectories, self.generator))
                    for _ in range(cfg.vae.updates_per_iteration)
                ]
                log.update({k: float(np.mean([x[k] for x in losses])) for k in losses[0]})
        return log

    def _excess_action_energy(self, actions: np.ndarray) -> np.ndarray:
        """|a|² − |clip(a)|² per step of sampled (T, N, A) actions: what a control cost on the sampled action
        charges beyond the task's cost on the clipped one."""
        a = actions.astype(np.float64)
        clipped = np.clip(a, *self.action_bounds)
        return np.sum(np.square(a), axis=-1) - np.sum(np.square(clipped), axis=-1)

    def _store_trajectories(self, rollout, lasts, buffer) -> None:
        """Cuts the rollout at BAMDP episode ends (synchronous across envs) into whole trajectories."""
        if not (lasts.all(axis=1) | ~lasts.any(axis=1)).all():
            raise RuntimeError("BAMDP episodes must end on the same step in every env")
        pieces = {
            "state": rollout["state"].numpy(),
            "next_state": rollout["next_state"].numpy(),
            "actions": rollout["actions"].numpy(),
            "rewards": rollout["rewards"].numpy(),
        }
        tasks = rollout["tasks"]
        start = 0
        chunks = self._episode_chunks
        for t in np.flatnonzero(lasts[:, 0]):
            chunks.append({k: v[start : t + 1] for k, v in pieces.items()})
            whole = {k: np.concatenate([c[k] for c in chunks]) for k in pieces}
            states = np.concatenate([whole["state"], whole["next_state"][-1:]])
            buffer.add(states, whole["actions"], whole["rewards"], None if tasks is None else tasks[t])
            chunks.clear()
            start = t + 1
        if start < lasts.shape[0]:
            chunks.append({k: v[start:] for k, v in pieces.items()})

    # Checkpoints --------------------------------------------------------------------------------------
    def _modules_state(self, deployable: bool = False) -> dict:
        """Networks and statistics; `deployable` leaves out what only training needs (a bonus's input
        buffer and optimiser: up to buffer_size inputs, which a saved agent does not carry)."""
        bonuses = [b.state_dict() for b in self.bonuses]
        if deployable:
            pairs = zip(self.bonuses, bonuses, strict=True)
            bonuses = [b.deployable(s) if hasattr(b, "deployable") else s for b, s in pairs]
        return {
            "model": self.model.state_dict(),
            "belief": self.belief.state_dict(),
            "bonuses": bonuses,
            "obs_stats": self.obs_stats.state_dict(),
        }

    def _load_modules_state(self, state: dict) -> None:
        self.model.load_state_dict(state["model"])
        self.belief.load_state_dict(state["belief"])
        for b, s in zip(self.bonuses, state["bonuses"], strict=True):
            b.load_state_dict(s)
        self.obs_stats.load_state_dict(state["obs_stats"])

    def _save_training_state(
        self, path, task, seed, iteration, env, carry, history, ext_scaler, bonus_scalers, buffer
    ) -> None:
        state = {
            "config": config_lib.to_dict(self.config),
            "task": task,
            "seed": seed,
            "frames": self.total_frames,
            "iteration": iteration,
            "modules": self._modules_state(),
            "optimizer": self.optimizer.state_dict(),
            "env": env.state_dict(),
            "carry": carry,
            "episode_chunks": list(self._episode_chunks),
            "history": history,
            "ext_scaler": ext_scaler.state_dict(),
            "bonus_scalers": [s.state_dict() for s in bonus_scalers],
            "buffer": buffer.items,
            "generator": self.generator.get_state(),
            "torch_rng": torch.get_rng_state(),
        }
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        serialization.save(state, tmp, kind="checkpoint")
        os.replace(tmp, path)  # atomic: a crash leaves the previous checkpoint intact

    def _load_training_state(self, saved, env, ext_scaler, bonus_scalers, buffer) -> None:
        self._load_modules_state(saved["modules"])
        self.optimizer.load_state_dict(saved["optimizer"])
        env.load_state_dict(saved["env"])
        ext_scaler.load_state_dict(saved["ext_scaler"])
        for s, st in zip(bonus_scalers, saved["bonus_scalers"], strict=True):
            s.load_state_dict(st)
        buffer.items = list(saved["buffer"])
        self._episode_chunks = list(saved["episode_chunks"])
        self.generator.set_state(saved["generator"])
        torch.set_rng_state(saved["torch_rng"])

    def save(self, path: str | os.PathLike) -> None:
        """Saves what deployment needs: config, specs and trained networks/statistics (data only)."""
        if not self._built:
            raise RuntimeError("nothing to save: the agent has not been trained or loaded")
        serialization.save(
            {
                "name": self.name,
                "config": config_lib.to_dict(self.config),
                "obs_spec": self.obs_spec,
                "action_bounds": self.action_bounds,
                "position_keys": self.position_keys,
                "modules": self._modules_state(deployable=True),
            },
            path,
            kind="agent",
        )

    @classmethod
    def load(cls, path: str | os.PathLike) -> Agent:
        """Loads an agent saved with `save`. The file is read as data only: a file that would run code
        when unpickled is refused with `serialization.UnsafeFileError`."""
        from dm_env import specs

        saved = serialization.load(path, kind="agent")
        agent = cls(config_lib.from_dict(AgentConfig, saved["config"]), saved["name"])
        obs_spec = {k: specs.Array(shape, np.dtype(dtype), name=k) for k, (shape, dtype) in saved["obs_spec"].items()}
        low, high = saved["action_bounds"]
        bounds = specs.BoundedArray(low.shape, np.float64, low, high)
        agent._build(obs_spec, bounds, seed=0, position_keys=saved.get("position_keys"))
        agent._load_modules_state(saved["modules"])
        return agent
