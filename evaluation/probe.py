"""Belief quality: how well a learned belief (variBAD's latent, RL²'s hidden state) encodes the exact
posterior, measured by a logistic-regression probe on held-out deployments.

The probe maps the agent's belief features at each step to a distribution over the prior's support and
is fit (soft targets: the exact posterior) on half of the deployments and scored on the other half.
Reported: the excess cross-entropy KL(exact ‖ probe) in nats (0 = the features determine the exact
belief) overall, before and after the first informative step (where the exact belief first changes),
and the accuracy of the probe's most likely task after it (where the exact belief is one-hot); and the
same per step of the BAMDP episode (`probe_kl_per_step`, `probe_accuracy_per_step`: mean over the test
deployments; accuracy counts informed steps only, None where no test deployment is informed yet).
"""

from __future__ import annotations

import numpy as np
import torch


def fit_probe(
    features: np.ndarray,
    targets: np.ndarray,
    *,
    steps: int = 500,
    lr: float = 0.05,
    weight_decay: float = 1e-4,
    seed: int = 0,
) -> torch.nn.Module:
    """Multinomial logistic regression on standardised features, trained on soft targets."""
    g = torch.Generator().manual_seed(seed)
    x = torch.as_tensor(features, dtype=torch.float32)
    y = torch.as_tensor(targets, dtype=torch.float32)
    mean, std = x.mean(0), x.std(0) + 1e-6
    linear = torch.nn.Linear(x.shape[1], y.shape[1])
    with torch.no_grad():
        linear.weight.copy_(0.01 * torch.randn(linear.weight.shape, generator=g))
        linear.bias.zero_()
    model = torch.nn.Sequential(_Standardise(mean, std), linear)
    optimizer = torch.optim.Adam(linear.parameters(), lr=lr, weight_decay=weight_decay)
    for _ in range(steps):
        loss = -(y * torch.log_softmax(model(x), -1)).sum(-1).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    return model


class _Standardise(torch.nn.Module):
    def __init__(self, mean, std):
        super().__init__()
        self.register_buffer("mean", mean)
        self.register_buffer("std", std)

    def forward(self, x):
        return (x - self.mean) / self.std


def _kl(targets: np.ndarray, log_probs: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.where(targets > 0, targets * (np.log(targets) - log_probs), 0.0)
    return terms.sum(-1)


def belief_quality(features: np.ndarray, exact: np.ndarray) -> dict:
    """Probe scores from (T, M, F) belief features and (T, M, B) exact beliefs of M deployments.

    Deployments alternate between the probe's training and test halves (so both see every task).
    """
    t_len, m = exact.shape[:2]
    if m < 2:
        raise ValueError("belief_quality needs at least two deployments (a train and a test half)")
    if features.shape[-1] == 0:
        features = np.zeros((*features.shape[:2], 1))
    train, test = np.arange(0, m, 2), np.arange(1, m, 2)
    probe = fit_probe(features[:, train].reshape(-1, features.shape[-1]), exact[:, train].reshape(-1, exact.shape[-1]))
    with torch.no_grad():
        log_probs = torch.log_softmax(probe(torch.as_tensor(features[:, test], dtype=torch.float32)), -1).numpy()
    target = exact[:, test]
    kl = _kl(target, log_probs)  # (T, M_test)
    changed = np.any(np.abs(target - target[:1]) > 1e-9, axis=-1)  # the exact belief has moved from the prior
    informed = np.cumsum(changed, axis=0) > 0
    after = kl[informed]
    hits = log_probs.argmax(-1) == target.argmax(-1)
    correct = hits[informed]
    informed_count = informed.sum(1)
    accuracy_per_step = np.where(informed_count > 0, (hits & informed).sum(1) / np.maximum(informed_count, 1), np.nan)
    return {
        "probe_kl_per_step": kl.mean(1).tolist(),
        "probe_accuracy_per_step": [None if np.isnan(a) else float(a) for a in accuracy_per_step],
        "probe_kl": float(kl.mean()),
        "probe_kl_before": float(kl[~informed].mean()) if (~informed).any() else None,
        "probe_kl_after": float(after.mean()) if after.size else None,
        "probe_accuracy_after": float(correct.mean()) if correct.size else None,
        "informed_fraction": float(informed.mean()),
    }
