"""Hyper-state coverage: how much of a discretised (x-position × exact belief) grid meta-training has
visited — pseudo-exploration made visible (the paper's argument, measured).

Cells are `x_bins` equal bins of the x-displacement over [-x_range, x_range] (values beyond fall in the
edge bins) × `belief_bins` equal bins of P(forward) (the exact belief's last component).
"""

from __future__ import annotations

import numpy as np


class HyperStateCoverage:
    """Cumulative set of visited (x, belief) cells."""

    def __init__(
        self,
        x_range: float = 20.0,
        x_bins: int = 40,
        belief_bins: int = 3,
        x_key: str = "x_displacement",
        belief_key: str = "belief",
    ):
        self.x_range, self.x_bins, self.belief_bins = x_range, x_bins, belief_bins
        self.x_key, self.belief_key = x_key, belief_key
        self.visited = np.zeros((x_bins, belief_bins), dtype=bool)

    def applies_to(self, observations: dict) -> bool:
        return self.x_key in observations and self.belief_key in observations

    def cells(self, observations: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(observations[self.x_key])[..., 0].ravel()
        b = np.asarray(observations[self.belief_key])[..., -1].ravel()
        xi = np.clip(((x + self.x_range) / (2 * self.x_range) * self.x_bins).astype(int), 0, self.x_bins - 1)
        bi = np.clip((b * self.belief_bins).astype(int), 0, self.belief_bins - 1)
        return xi, bi

    def update(self, observations: dict[str, np.ndarray]) -> None:
        """Marks the cells of a rollout's observations ((T, N, ...) arrays) as visited."""
        xi, bi = self.cells(observations)
        self.visited[xi, bi] = True

    def fraction(self) -> float:
        return float(self.visited.mean())
