"""`varibad`: variBAD's VAE; the policy sees the posterior (mean, logvar), detached."""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from hyperstate.agents.beliefs.base import Trajectories, no_params, register_belief, where
from hyperstate.agents.config import VAEConfig
from hyperstate.agents.networks import mlp


class VariationalEncoder(nn.Module):
    """variBAD's encoder: GRU over embedded (a_t, r_t, s_{t+1}) → Gaussian posterior (mean, logvar)."""

    def __init__(self, state_dim: int, action_dim: int, config: VAEConfig):
        super().__init__()
        self.state_embed = nn.Linear(state_dim, config.state_embed)
        self.action_embed = nn.Linear(action_dim, config.action_embed)
        self.reward_embed = nn.Linear(1, config.reward_embed)
        self.gru = nn.GRU(config.action_embed + config.reward_embed + config.state_embed, config.gru_hidden)
        self.head = nn.Linear(config.gru_hidden, 2 * config.latent_dim)
        self.hidden = config.gru_hidden
        self.latent_dim = config.latent_dim

    def embed(self, action, reward, next_state):
        return torch.cat(
            [
                F.relu(self.action_embed(action)),
                F.relu(self.reward_embed(reward)),
                F.relu(self.state_embed(next_state)),
            ],
            dim=-1,
        )

    def step(self, h, action, reward, next_state):
        """One transition for a batch: h (N, H) → (h', mean, logvar).

        The same computation as `sequence` over one step (identical results), written with plain
        functions (`gru_cell`, `F.linear`): called once per rollout step, module overhead dominates it."""
        embedded = torch.cat(
            [
                F.relu(F.linear(action, self.action_embed.weight, self.action_embed.bias)),
                F.relu(F.linear(reward, self.reward_embed.weight, self.reward_embed.bias)),
                F.relu(F.linear(next_state, self.state_embed.weight, self.state_embed.bias)),
            ],
            dim=-1,
        )
        gru = self.gru
        h = torch.gru_cell(embedded, h, gru.weight_ih_l0, gru.weight_hh_l0, gru.bias_ih_l0, gru.bias_hh_l0)
        mean, logvar = F.linear(h, self.head.weight, self.head.bias).chunk(2, dim=-1)
        return h, mean, logvar

    def sequence(self, actions, rewards, next_states):
        """Posteriors of whole trajectories (B, T, ·) → mean, logvar of shape (B, T+1, latent), prior first."""
        b = actions.shape[0]
        out, _ = self.gru(self.embed(actions, rewards, next_states).transpose(0, 1))
        mean, logvar = self.head(out.transpose(0, 1)).chunk(2, dim=-1)
        zeros = torch.zeros(b, 1, self.latent_dim)
        return torch.cat([zeros, mean], dim=1), torch.cat([zeros, logvar], dim=1)


def gaussian_kl(mean_q, logvar_q, mean_p, logvar_p) -> torch.Tensor:
    """KL(N(mean_q, exp logvar_q) || N(mean_p, exp logvar_p)), summed over the last axis."""
    return 0.5 * torch.sum(
        logvar_p - logvar_q + (logvar_q.exp() + (mean_q - mean_p) ** 2) / logvar_p.exp() - 1.0, dim=-1
    )


def kl_to_previous(mean: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """(B, T+1) KL of each posterior to the one before it, the first to N(0, I) (eq. 7)."""
    prev_mean = torch.cat([torch.zeros_like(mean[:, :1]), mean[:, :-1]], dim=1)
    prev_logvar = torch.cat([torch.zeros_like(logvar[:, :1]), logvar[:, :-1]], dim=1)
    return gaussian_kl(mean, logvar, prev_mean, prev_logvar)


@register_belief("varibad")
class VariBADBelief:
    """variBAD: the posterior of a VAE over the task, trained with the ELBO of eq. (7)."""

    trainable = True
    reads_true_task = False
    decodes_reward = True

    @classmethod
    def build(cls, *, state_dim, action_dim, vae, generator, params, **_):
        no_params(cls.name, params)
        return cls(state_dim, action_dim, vae, generator)

    def __init__(self, state_dim: int, action_dim: int, config: VAEConfig, seed_generator: torch.Generator):
        self.config = config
        self.feature_dim = 2 * config.latent_dim
        self.encoder = VariationalEncoder(state_dim, action_dim, config)
        self.decoder = self._make_decoder(state_dim, action_dim)
        self.modules = nn.ModuleList([self.encoder, self.decoder])
        self.optimizer = torch.optim.Adam(self.modules.parameters(), lr=config.lr)
        self._gen = seed_generator

    def _make_decoder(self, state_dim: int, action_dim: int) -> nn.Module:
        # Reward decoder p(r_j | z, s_j, a_j, s_{j+1}); state decoder optional.
        c = self.config
        out = 1 + (state_dim if c.decode_state else 0)
        return mlp([c.latent_dim + 2 * state_dim + action_dim, *c.decoder_hidden, out], nn.ReLU)

    # Online use --------------------------------------------------------------------------------
    def initial_state(self, n, obs):
        zeros = torch.zeros(n, self.config.latent_dim)
        return (torch.zeros(n, self.config.gru_hidden), zeros, zeros.clone())

    def update(self, state, transition):
        with torch.no_grad():
            return self.encoder.step(state[0], transition.action, transition.reward, transition.next_state)

    def reset_where(self, state, mask, obs):
        fresh = self.initial_state(len(mask), obs)
        return tuple(where(mask, f, s) for f, s in zip(fresh, state, strict=True))

    def features(self, state):
        return torch.cat([state[1], state[2]], dim=-1)

    def policy_parameters(self):
        return []

    def sequence_features(self, rollout, env_index):
        return rollout.features[:, env_index]

    def replay_features(self, trajectories: Trajectories) -> torch.Tensor:
        """(B, T+1, F) posteriors of stored trajectories under the current encoder, prior first."""
        with torch.no_grad():
            mean, logvar = self.encoder.sequence(trajectories.actions, trajectories.rewards, trajectories.states[:, 1:])
        return torch.cat([mean, logvar], dim=-1)

    # Training ---------------------------------------------------------------------------------
    def sample_latent(self, mean: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
        noise = torch.randn(mean.shape, generator=self._gen)
        return mean + noise * torch.exp(0.5 * logvar)

    def decode(self, z, state, action, next_state):
        return self.decoder(torch.cat([z, state, action, next_state], dim=-1))

    def reconstruction_error(self, features, state, action, next_state, reward) -> torch.Tensor:
        """Squared error of the reward predicted from a latent sample of the posterior `features`."""
        mean, logvar = features.chunk(2, dim=-1)
        with torch.no_grad():
            pred = self.decode(self.sample_latent(mean, logvar), state, action, next_state)[..., :1]
        return (pred - reward).pow(2).sum(-1)

    def _subsample(self, n: int, k: int) -> torch.Tensor:
        if k <= 0 or k >= n:
            return torch.arange(n)
        return torch.randperm(n, generator=self._gen)[:k].sort().values

    def elbo_terms(self, trajectories: Trajectories) -> tuple[torch.Tensor, torch.Tensor]:
        """(reconstruction loss, KL), each averaged over the chosen ELBO timesteps and the batch."""
        s, a, r = trajectories.states, trajectories.actions, trajectories.rewards
        mean, logvar = self.encoder.sequence(a, r, s[:, 1:])  # (B, T+1, L)
        t_len = a.shape[1]
        kl = kl_to_previous(mean, logvar)  # (B, T+1)
        elbo_t = self._subsample(t_len + 1, self.config.subsample_elbos)
        dec_j = self._subsample(t_len, self.config.subsample_decodes)
        z = self.sample_latent(mean[:, elbo_t], logvar[:, elbo_t])  # (B, E, L)
        b, e = z.shape[:2]
        d = len(dec_j)
        # Every latent decodes every chosen transition of the trajectory (past and future).
        inputs = torch.cat(
            [
                z[:, :, None].expand(b, e, d, z.shape[-1]),
                s[:, dec_j][:, None].expand(b, e, d, s.shape[-1]),
                a[:, dec_j][:, None].expand(b, e, d, a.shape[-1]),
                s[:, dec_j + 1][:, None].expand(b, e, d, s.shape[-1]),
            ],
            dim=-1,
        )
        pred = self.decoder(inputs)
        target = r[:, dec_j][:, None].expand(b, e, d, 1)
        if self.config.decode_state:
            target = torch.cat([target, s[:, dec_j + 1][:, None].expand(b, e, d, s.shape[-1])], dim=-1)
        recon = (pred - target).pow(2).sum(-1).sum(-1).mean()  # sum over decodes, mean over ELBOs and batch
        return recon, kl[:, elbo_t].mean()

    def train_step(self, trajectories):
        recon, kl = self.elbo_terms(trajectories)
        loss = recon + self.config.kl_weight * kl
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        return {"vae/reconstruction": recon.item(), "vae/kl": kl.item(), "vae/loss": loss.item()}

    def state_dict(self):
        return {"modules": self.modules.state_dict(), "optimizer": self.optimizer.state_dict()}

    def load_state_dict(self, state):
        self.modules.load_state_dict(state["modules"])
        self.optimizer.load_state_dict(state["optimizer"])
