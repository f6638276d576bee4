"""Eq. (4): the reward PPO sees — the extrinsic reward and each bonus divided by the std of its own running
discounted return, bonuses weighted by λ and annealed on their schedules."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hyperstate.agents import config as config_lib
from hyperstate.agents.config import BonusConfig
from hyperstate.agents.normalization import ReturnScaler


def combine_rewards(
    extrinsic: np.ndarray,
    bonuses: list[np.ndarray],
    *,
    weights: list[float],
    anneal: float | Sequence[float],
    lasts: np.ndarray,
    ext_scaler: ReturnScaler | None,
    bonus_scalers: list[ReturnScaler],
    reward_clip: float,
    bonus_clips: Sequence[float | None] | None = None,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Eq. (4): r + Σ_i λ_i r_i, each stream divided by the std of its own running discounted return.

    The extrinsic stream is normalised and clipped to ±`reward_clip` (unless `ext_scaler` is None);
    each bonus is normalised, clipped to ±`bonus_clips[i]` where one is given, weighted, and multiplied by
    its annealing factor (`anneal`: one for all bonuses, or one per bonus; 1 − progress when annealing).
    Returns the combined (T, N) reward and the normalised (and clipped) bonuses.
    """
    anneals = [float(anneal)] * len(bonuses) if np.isscalar(anneal) else list(anneal)
    clips = list(bonus_clips) if bonus_clips is not None else [None] * len(bonuses)
    reward = extrinsic
    if ext_scaler is not None:
        reward = np.clip(ext_scaler.scale(extrinsic, lasts), -reward_clip, reward_clip)
    scaled = [scaler.scale(b, lasts) for b, scaler in zip(bonuses, bonus_scalers, strict=True)]
    scaled = [b if clip is None else np.clip(b, -clip, clip) for b, clip in zip(scaled, clips, strict=True)]
    for weight, factor, b in zip(weights, anneals, scaled, strict=True):
        reward = reward + factor * weight * b
    return reward, scaled


def bonus_anneal_factor(bonus: BonusConfig, anneal_all: bool, progress: float) -> float:
    """The weight multiplier of one bonus at `progress` (0 at the start of training, 1 at the end): linear
    to 0 at `bonus.anneal_until`, or over the whole run when the agent anneals every bonus; else 1."""
    until = bonus.anneal_until if bonus.anneal_until is not None else (1.0 if anneal_all else None)
    return 1.0 if until is None else max(0.0, 1.0 - progress / until)


def intrinsic_discount(p: config_lib.PPOConfig) -> float:
    """The discount of the bonuses' returns: the policy's, or the intrinsic value head's."""
    return p.gamma if p.intrinsic_gamma is None else p.intrinsic_gamma
