"""`oracle` and `task_aware`: privileged information handed to the policy as its belief — the task's exact
belief (the paper's Belief Oracle), or the true task (the reference that knows it)."""

from __future__ import annotations

import numpy as np

from hyperstate.agents.beliefs.base import Stateless, no_params, register_belief, where


@register_belief("oracle")
class OracleBelief(Stateless):
    """The exact belief, read from the task's privileged `belief` observation.

    With `key="task"` it hands over the true task instead: the task-aware reference policy.
    """

    key = "belief"
    missing = "the oracle belief needs a task with an exact belief (privileged `belief` observation)"

    def __init__(self, dim: int):
        self.feature_dim = dim

    @classmethod
    def build(cls, *, obs_spec, params, **_):
        no_params(cls.name, params)
        if cls.key not in obs_spec:
            raise ValueError(cls.missing)
        return cls(int(np.prod(obs_spec[cls.key].shape)))

    def initial_state(self, n, obs):
        return obs[self.key].clone()

    def update(self, state, transition):
        return transition.next_obs[self.key].clone()

    def reset_where(self, state, mask, obs):
        return where(mask, obs[self.key], state)

    def features(self, state):
        return state


@register_belief("task_aware")
class TaskAwareBelief(OracleBelief):
    """The true task parameters, read from the task's privileged `task` observation: the reference
    policy that knows the task (not a meta-learner)."""

    key = "task"
    missing = "task_aware needs the task's privileged `task` observation"
    reads_true_task = True
