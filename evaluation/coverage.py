"""Hyper-state coverage: how much of a discretised (position × exact belief) grid meta-training has
visited — pseudo-exploration made visible (the paper's argument, measured).

The grid is what the task declares (`suite.register(..., coverage=suite.Coverage(...))`): equal bins of a
one-number position over [low, high] (values beyond fall in the edge bins) × equal bins of the exact
belief's last component. A task that declares none has no coverage.
"""

from __future__ import annotations

import numpy as np

from hyperstate import suite


class HyperStateCoverage:
    """Cumulative set of visited (position, belief) cells of a `suite.Coverage` grid."""

    def __init__(self, grid: suite.Coverage):
        self.grid = grid
        self.visited = np.zeros((grid.bins, grid.belief_bins), dtype=bool)

    @classmethod
    def for_task(cls, task: str) -> HyperStateCoverage | None:
        """The coverage of the grid task `task` declares, or None if it declares none."""
        grid = suite.coverage(task)
        return None if grid is None else cls(grid)

    def applies_to(self, observations: dict) -> bool:
        return self.grid.key in observations and self.grid.belief_key in observations

    def cells(self, observations: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        g = self.grid
        x = np.asarray(observations[g.key])[..., 0].ravel()
        b = np.asarray(observations[g.belief_key])[..., -1].ravel()
        xi = np.clip(((x - g.low) / (g.high - g.low) * g.bins).astype(int), 0, g.bins - 1)
        bi = np.clip((b * g.belief_bins).astype(int), 0, g.belief_bins - 1)
        return xi, bi

    def update(self, observations: dict[str, np.ndarray]) -> None:
        """Marks the cells of a rollout's observations ((T, N, ...) arrays) as visited."""
        if self.applies_to(observations):
            xi, bi = self.cells(observations)
            self.visited[xi, bi] = True

    def fraction(self) -> float:
        return float(self.visited.mean())
