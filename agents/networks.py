"""Small network builders shared by the components."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn


def mlp(sizes: list[int], activation: type[nn.Module] = nn.Tanh, out_gain: float = 1.0) -> nn.Sequential:
    """Linear layers with `activation` between them (none after the last), orthogonal init."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        linear = nn.Linear(a, b)
        last = i == len(sizes) - 2
        nn.init.orthogonal_(linear.weight, out_gain if last else np.sqrt(2))
        nn.init.zeros_(linear.bias)
        layers.append(linear)
        if not last:
            layers.append(activation())
    return nn.Sequential(*layers)


class Embed(nn.Module):
    """Linear + ReLU embedding, or identity when `size` is 0."""

    def __init__(self, in_dim: int, size: int):
        super().__init__()
        self.out_dim = size if size and in_dim else in_dim
        self.net = nn.Sequential(nn.Linear(in_dim, size), nn.ReLU()) if size and in_dim else nn.Identity()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)
