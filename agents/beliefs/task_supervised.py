"""`task_supervised`: variBAD's encoder trained to predict the true task parameters (Humplik et al. 2019)."""

from __future__ import annotations

import numpy as np
from torch import nn

from hyperstate.agents.beliefs.base import no_params, register_belief
from hyperstate.agents.beliefs.varibad import VariBADBelief, kl_to_previous
from hyperstate.agents.networks import mlp


@register_belief("task_supervised")
class TaskSupervisedBelief(VariBADBelief):
    """The variBAD encoder trained to regress the true task parameters from every latent (plus KL)."""

    decodes_reward = False

    @classmethod
    def build(cls, *, state_dim, action_dim, obs_spec, vae, generator, params, **_):
        no_params(cls.name, params)
        if "task" not in obs_spec:
            raise ValueError("task_supervised needs the task's privileged `task` observation")
        return cls(state_dim, action_dim, vae, generator, int(np.prod(obs_spec["task"].shape)))

    def __init__(self, state_dim, action_dim, config, seed_generator, task_dim: int):
        self._task_dim = task_dim
        super().__init__(state_dim, action_dim, config, seed_generator)

    def _make_decoder(self, state_dim, action_dim):
        return mlp([self.config.latent_dim, *self.config.decoder_hidden, self._task_dim], nn.ReLU)

    def elbo_terms(self, trajectories):
        s, a, r = trajectories.states, trajectories.actions, trajectories.rewards
        if trajectories.tasks is None:
            raise ValueError("task_supervised needs the task's privileged `task` observation")
        mean, logvar = self.encoder.sequence(a, r, s[:, 1:])
        kl = kl_to_previous(mean, logvar)
        elbo_t = self._subsample(a.shape[1] + 1, self.config.subsample_elbos)
        pred = self.decoder(self.sample_latent(mean[:, elbo_t], logvar[:, elbo_t]))
        error = (pred - trajectories.tasks[:, None]).pow(2).sum(-1).mean()
        return error, kl[:, elbo_t].mean()

    def reconstruction_error(self, features, state, action, next_state, reward):
        raise NotImplementedError("task_supervised has no reward decoder; use the vae_error bonus with varibad")
