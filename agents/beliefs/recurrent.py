"""`recurrent`: RL²'s GRU, trained by the RL loss through time."""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from hyperstate.agents.beliefs.base import no_params, register_belief, where
from hyperstate.agents.config import RecurrentConfig


@register_belief("recurrent")
class RecurrentBelief:
    """RL²: a GRU over (s_{t+1}, a_t, r_t) whose hidden state (ReLU) is the policy's task summary.

    The hidden state is kept across MDP episodes and reset only at BAMDP starts; the MDP-episode
    boundary (RL²'s "done" input) reaches the GRU through the `inner_episode` observation in s_{t+1}.
    """

    trainable = False  # by the RL loss only (its parameters are `policy_parameters`)
    reads_true_task = False
    decodes_reward = False

    @classmethod
    def build(cls, *, state_dim, action_dim, recurrent, params, **_):
        no_params(cls.name, params)
        return cls(state_dim, action_dim, recurrent)

    def __init__(self, state_dim: int, action_dim: int, config: RecurrentConfig):
        self.config = config
        self.feature_dim = config.hidden
        self.embed = nn.ModuleDict(
            {
                "state": nn.Linear(state_dim, config.state_embed),
                "action": nn.Linear(action_dim, config.action_embed),
                "reward": nn.Linear(1, config.reward_embed),
            }
        )
        self.gru = nn.GRU(config.state_embed + config.action_embed + config.reward_embed, config.hidden)
        self.modules = nn.ModuleList([self.embed, self.gru])

    def _input(self, next_state, action, reward):
        return torch.cat(
            [
                F.relu(self.embed["state"](next_state)),
                F.relu(self.embed["action"](action)),
                F.relu(self.embed["reward"](reward)),
            ],
            dim=-1,
        )

    def initial_state(self, n, obs):
        return torch.zeros(n, self.config.hidden)

    def update(self, state, transition):
        x = self._input(transition.next_state, transition.action, transition.reward)
        return self.gru(x[None], state[None])[1][0]

    def reset_where(self, state, mask, obs):
        return where(mask, torch.zeros_like(state), state)

    def features(self, state):
        return F.relu(state)

    def policy_parameters(self):
        return list(self.modules.parameters())

    def sequence_features(self, rollout, env_index):
        """Re-runs the GRU over the rollout from its stored start state, with gradients.

        BAMDP episodes start on the same step in every env, so the rollout splits into segments
        between starts, each one call of the cuDNN-style sequence GRU.
        """
        h = rollout.belief_state0[env_index]
        inputs = self._input(
            rollout.next_state[:, env_index],
            rollout.actions[:, env_index],
            rollout.rewards[:, env_index, None],
        )
        starts = rollout.starts[:, env_index]
        if not bool((starts.all(dim=1) | ~starts.any(dim=1)).all()):
            raise RuntimeError("BAMDP episodes must start on the same step in every env")
        bounds = [0, *[t for t in torch.nonzero(starts[:, 0]).flatten().tolist() if t > 0], inputs.shape[0]]
        out = []
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            if bool(starts[a, 0]):
                h = torch.zeros_like(h)
            seq, last = self.gru(inputs[a:b], h[None])
            # Features at step t come from the hidden state before consuming transition t.
            out.append(torch.cat([h[None], seq[:-1]]))
            h = last[0]
        return F.relu(torch.cat(out))

    def train_step(self, trajectories):
        return {}

    def state_dict(self):
        return {"modules": self.modules.state_dict()}

    def load_state_dict(self, state):
        self.modules.load_state_dict(state["modules"])
