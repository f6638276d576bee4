"""The deployable policy: networks, belief and bonus components of an agent, and what evaluation touches.

`Policy` is what a trained agent is at deployment: `act` (from the prior belief, taking in each transition),
`belief_features`, `save` / `load` (data-only files), and `bonus_values` for diagnostics. It holds the
components an `AgentConfig` names — PPO's actor-critic, one belief, the bonuses (whose networks come along,
so that diagnostics can evaluate them) — and the observation statistics. Training lives in
`agents/trainer.py`; `agents.Agent` is a Policy that can also `train`.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any

import numpy as np
import torch

from hyperstate import suite
from hyperstate.agents import config as config_lib
from hyperstate.agents import serialization
from hyperstate.agents.beliefs import Transition, make_belief
from hyperstate.agents.bonuses import BonusInput, make_bonus
from hyperstate.agents.config import AgentConfig
from hyperstate.agents.normalization import RunningMeanStd
from hyperstate.agents.ppo import ActorCritic

PRIVILEGED_KEYS = ("belief", "task")


@dataclasses.dataclass
class AgentState:
    """Deployment state of a batch of agents: belief state and the previous action."""

    belief: Any
    prev_action: torch.Tensor


class Policy:
    """An agent's networks and components, built for one task's observation and action specs."""

    def __init__(self, config: AgentConfig, name: str = "custom"):
        self.config = config
        self.name = name
        self._built = False

    # Construction ----------------------------------------------------------------------------------
    def build(self, obs_spec: dict, action_spec, seed: int, position_keys: tuple[str, ...] | None = None) -> None:
        """Creates the networks, belief and bonuses for a task's observation and action specs (the trainer
        calls it; `load` does for a saved agent)."""
        cfg = self.config
        self.position_keys = position_keys
        torch.manual_seed(seed if cfg.init_seed is None else cfg.init_seed)  # every network's initial weights
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
        self.belief = self._make_belief(obs_spec, self.generator)
        if cfg.ppo.minibatch_unit == "transitions" and self.belief.policy_parameters():
            raise ValueError(
                f"ppo.minibatch_unit 'transitions' needs a belief whose features are fixed in the rollout; the "
                f"{cfg.belief!r} belief is trained through time by the RL loss: use 'envs'"
            )
        self.model = self._actor_critic()
        if cfg.bonus_init_seed is not None:
            # Replay the draws a run with that init seed makes before its bonuses, so they start as its do.
            torch.manual_seed(cfg.bonus_init_seed)
            self._make_belief(obs_spec, torch.Generator())
            self._actor_critic()
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

    def _make_belief(self, obs_spec: dict, generator: torch.Generator):
        cfg = self.config
        return make_belief(
            cfg.belief,
            state_dim=self.state_dim,
            action_dim=self.action_dim,
            obs_spec=obs_spec,
            vae=cfg.vae,
            recurrent=cfg.recurrent,
            generator=generator,
            params=cfg.belief_params,
        )

    def _actor_critic(self) -> ActorCritic:
        cfg = self.config
        return ActorCritic(self.state_dim, self.belief.feature_dim, self.action_dim, cfg.ppo, cfg.value_heads)

    def state_vector(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """The policy's state input: its state keys of a batch of observations, flattened, (N, state_dim)."""
        return np.concatenate(
            [np.asarray(obs[k], np.float64).reshape(len(obs[k]), -1) for k in self.state_keys], axis=-1
        )

    def normalized(self, state: np.ndarray) -> torch.Tensor:
        """`state_vector` output as the networks see it (running-normalised when `ppo.norm_obs`)."""
        x = self.obs_stats.normalize(state) if self.config.ppo.norm_obs else state
        return torch.as_tensor(x, dtype=torch.float32)

    @staticmethod
    def tensors(obs: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
        """The privileged observation keys as tensors: all a belief reads besides the state."""
        return {k: torch.as_tensor(np.asarray(obs[k]), dtype=torch.float32) for k in PRIVILEGED_KEYS if k in obs}

    # Deployment -------------------------------------------------------------------------------------
    def initial_state(self, obs: dict[str, np.ndarray]) -> AgentState:
        """The prior belief for a batch of first observations (the start of a BAMDP episode)."""
        t = self.tensors(obs)
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
            raw = self.state_vector(obs)
            if state is None:
                state = self.initial_state(obs)
            else:
                if reward is None:
                    raise ValueError("pass the previous step's reward with the state")
                transition = Transition(
                    state.prev_action,
                    torch.as_tensor(np.asarray(reward, np.float32).reshape(-1, 1)),
                    torch.as_tensor(raw, dtype=torch.float32),
                    self.tensors(obs),
                )
                state = AgentState(self.belief.update(state.belief, transition), state.prev_action)
            dist = self.model.distribution(self.normalized(raw), self.belief.features(state.belief))
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
        next_state = torch.as_tensor(self.state_vector(obs), dtype=torch.float32)
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

    def check_task(self, task: str, task_kwargs: dict | None = None) -> None:
        """Raises ValueError (naming what is missing) if this agent cannot run on `task`, e.g. the
        oracle belief on a task without an exact belief; builds nothing that training keeps."""
        env = suite.load(task, seed=0, privileged=True, **(task_kwargs or {}))
        probe = Policy(self.config, self.name)
        probe.build(env.observation_spec(), env.action_spec(), 0, suite.position_keys(task))

    # Saving ------------------------------------------------------------------------------------------
    def modules_state(self, deployable: bool = False) -> dict:
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

    def load_modules_state(self, state: dict) -> None:
        """Restores what `modules_state` returned."""
        self.model.load_state_dict(state["model"])
        self.belief.load_state_dict(state["belief"])
        for b, s in zip(self.bonuses, state["bonuses"], strict=True):
            b.load_state_dict(s)
        self.obs_stats.load_state_dict(state["obs_stats"])

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
                "modules": self.modules_state(deployable=True),
            },
            path,
            kind="agent",
        )

    @classmethod
    def load(cls, path: str | os.PathLike) -> Policy:
        """Loads an agent saved with `save`. The file is read as data only: a file that would run code
        when unpickled is refused with `serialization.UnsafeFileError`."""
        from dm_env import specs

        saved = serialization.load(path, kind="agent")
        agent = cls(config_lib.from_dict(AgentConfig, saved["config"]), saved["name"])
        obs_spec = {k: specs.Array(shape, np.dtype(dtype), name=k) for k, (shape, dtype) in saved["obs_spec"].items()}
        low, high = saved["action_bounds"]
        bounds = specs.BoundedArray(low.shape, np.float64, low, high)
        agent.build(obs_spec, bounds, seed=0, position_keys=saved.get("position_keys"))
        agent.load_modules_state(saved["modules"])
        return agent
