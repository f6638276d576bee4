"""`none`: no belief features (a Markov policy on the state)."""

from __future__ import annotations

import torch

from hyperstate.agents.beliefs.base import Stateless, no_params, register_belief


@register_belief("none")
class NoBelief(Stateless):
    """A Markov policy: no belief features."""

    def __init__(self, num_states: int):
        self.feature_dim = 0

    @classmethod
    def build(cls, *, state_dim, params, **_):
        no_params(cls.name, params)
        return cls(state_dim)

    def initial_state(self, n, obs):
        return torch.zeros(n, 0)

    def update(self, state, transition):
        return state

    def reset_where(self, state, mask, obs):
        return state

    def features(self, state):
        return state
