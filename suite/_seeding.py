"""Seeding helpers: every random draw in the suite goes through a `numpy.random.Generator`."""

from __future__ import annotations

import numpy as np

SeedLike = None | int | np.integer | np.random.SeedSequence | np.random.Generator


def as_generator(seed: SeedLike) -> np.random.Generator:
    """A `Generator` from an int, a `SeedSequence`, an existing `Generator` (returned as is) or None."""
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is None or isinstance(seed, (int, np.integer, np.random.SeedSequence)):
        if isinstance(seed, (int, np.integer)) and seed < 0:
            raise ValueError(f"seed must be non-negative, got {seed}")
        return np.random.default_rng(seed)
    raise TypeError(f"seed must be an int, SeedSequence, Generator or None, got {type(seed).__name__}")


def spawn_seeds(seed: SeedLike, n: int) -> list[np.random.SeedSequence]:
    """`n` independent child seeds of `seed`: the seeds of the copies in `suite.batch(..., seed)`."""
    if isinstance(seed, np.random.Generator):
        root = seed.bit_generator.seed_seq
    elif isinstance(seed, np.random.SeedSequence):
        root = seed
    else:
        as_generator(seed)  # validates the seed
        root = np.random.SeedSequence(seed)
    # Children are derived from the root's entropy and a spawn key, not from the root's spawn counter,
    # so calling this twice with the same seed gives the same children.
    return [
        np.random.SeedSequence(root.entropy, spawn_key=(*root.spawn_key, i), pool_size=root.pool_size) for i in range(n)
    ]
