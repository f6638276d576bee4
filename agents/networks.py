"""Small network builders shared by the components."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn


def normc_(weight: torch.Tensor, gain: float = 1.0) -> torch.Tensor:
    """OpenAI baselines' "normc" init, used by the reference code: N(0, 1) weights, each output unit's row
    rescaled to norm `gain`."""
    with torch.no_grad():
        weight.normal_(0.0, 1.0)
        weight *= gain / weight.pow(2).sum(1, keepdim=True).sqrt()
    return weight


def mlp(
    sizes: list[int],
    activation: type[nn.Module] = nn.Tanh,
    out_gain: float | None = 1.0,
    init: str = "orthogonal",
) -> nn.Sequential:
    """Linear layers with `activation` between them (none after the last), zero biases.

    `init` "orthogonal": orthogonal weights, gain sqrt(2) on hidden layers; "normc": `normc_` rows of norm
    `nn.init.calculate_gain(activation)` (5/3 for tanh), as the reference code. The last layer gets
    `out_gain`; None leaves it at PyTorch's default init (the reference's critic head).
    """
    if init == "orthogonal":
        init_weight, hidden_gain = nn.init.orthogonal_, np.sqrt(2)
    elif init == "normc":
        init_weight, hidden_gain = normc_, nn.init.calculate_gain(activation.__name__.lower())
    else:
        raise ValueError(f"mlp init must be 'orthogonal' or 'normc', got {init!r}")
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        linear = nn.Linear(a, b)
        last = i == len(sizes) - 2
        gain = out_gain if last else hidden_gain
        if gain is not None:
            init_weight(linear.weight, gain)
            nn.init.zeros_(linear.bias)
        layers.append(linear)
        if not last:
            layers.append(activation())
    return nn.Sequential(*layers)


class Embed(nn.Module):
    """Linear + `activation` (ReLU) embedding, or identity when `size` is 0. The Linear has PyTorch's default
    init, or orthogonal weights × `gain` and zero biases when a gain is given."""

    def __init__(self, in_dim: int, size: int, gain: float | None = None, activation: type[nn.Module] = nn.ReLU):
        super().__init__()
        self.out_dim = size if size and in_dim else in_dim
        self.net = nn.Sequential(nn.Linear(in_dim, size), activation()) if size and in_dim else nn.Identity()
        if gain is not None and size and in_dim:
            # On a forked RNG: the networks built after this one draw exactly what they draw without a gain.
            with torch.random.fork_rng(devices=[]):
                nn.init.orthogonal_(self.net[0].weight, gain)
            nn.init.zeros_(self.net[0].bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


# A layer of a plan: a Linear's (weight, bias) or an elementwise activation.
Layer = tuple[torch.Tensor, torch.Tensor] | Callable[[torch.Tensor], torch.Tensor]
_ACTIVATIONS: dict[type[nn.Module], Callable[[torch.Tensor], torch.Tensor]] = {nn.Tanh: torch.tanh, nn.ReLU: torch.relu}


def layer_plan(module: nn.Module) -> list[Layer]:
    """The layers of a `mlp`, an `Embed` or an `nn.Identity` as plain tensors and functions, for `run_plan`.

    The plan holds the module's own parameters (not copies), so it follows optimiser steps and
    `load_state_dict`; it runs the same kernels in the same order as the module, so results are identical.
    """
    if isinstance(module, Embed):
        return layer_plan(module.net)
    if isinstance(module, nn.Identity):
        return []
    if isinstance(module, nn.Linear):
        return [(module.weight, module.bias)]
    if type(module) in _ACTIVATIONS:
        return [_ACTIVATIONS[type(module)]]
    if isinstance(module, nn.Sequential):
        return [layer for child in module for layer in layer_plan(child)]
    raise TypeError(f"no plain-function form for {type(module).__name__}")


def run_plan(plan: list[Layer], x: torch.Tensor) -> torch.Tensor:
    """Applies a `layer_plan` to `x`: the module's forward without nn.Module call overhead, which at a
    rollout step's batch size (16 rows) costs about as much as the layers' arithmetic."""
    for layer in plan:
        x = F.linear(x, *layer) if isinstance(layer, tuple) else layer(x)
    return x
