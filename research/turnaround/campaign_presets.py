"""Presets of the turn-around campaign (research/turnaround/notebook.md) that are not rows of the Figure-2 grid.

`oracle_rh_prior20`: `oracle_rh` with its hyper-state RND prior scaled by 20 (H2's dose-response test: the
reference code's 5 never made the turn pay at 2e7 frames, the paper's 10 did in 2 of 3 seeds; seed 2 walked
back too slowly with either). Run 9 ran it from commit e5c5baa, where this file was
bench/turnaround/presets.py and `oracle_rh` still had prior 5 (the preset is the same either way).
Use with  --import research/turnaround/fig2_presets.py research/turnaround/campaign_presets.py
          (fig2.toml has a table for the former's row)
          --config research/turnaround/fig2.toml research/turnaround/configs/prior_20.toml

(`oracle_rh_rs`, `oracle_rh` plus `hyperx`'s state bonus (H8, H19), was defined here until 2026-12-02 and is
now a row of research/turnaround/fig2_presets.py, its bonus settings a table of research/turnaround/fig2.toml.)

The ablation of `oracle_rh_icml` (the reference code's oracle settings, which made the turn pay in 2 of 3
seeds where the seed presets rarely did), one group of its settings at a time back to `oracle_rh` under
research/turnaround/fig2.toml, the exploration noise (entropy 1e-4, control cost on the sampled action) kept as the
reference's in both (H14 already ran the noise alone on the seed preset):
`oracle_rh_icml_seed_bonus`: the seed preset's bonus (running-normalised inputs, prior output x10, weight 10,
no clip, not annealed, 4 predictor updates per iteration on a 1e5 buffer as fig2.toml), the reference's PPO.
`oracle_rh_icml_seed_ppo`: the reference's bonus, the seed preset's PPO (32 envs as fig2.toml, minibatches of
whole envs, per-minibatch advantage normalisation, the plain squared value loss).
Use with  --import research/turnaround/campaign_presets.py  --config research/turnaround/fig2_icml.toml
          research/turnaround/configs/schedule_5e7.toml
"""

from __future__ import annotations

import dataclasses

from hyperstate import agents
from hyperstate.agents.presets import HYPERSTATE_BONUS

# The campaign's `oracle_rh` was the seed paper's, today `oracle_rh_paper`.
_oracle_rh = agents.PRESETS["oracle_rh_paper"]
agents.register_preset(
    "oracle_rh_prior20",
    dataclasses.replace(_oracle_rh, bonuses=(dataclasses.replace(_oracle_rh.bonuses[0], prior_scale=20.0),)),
)

_oracle_rh_icml = agents.PRESETS["oracle_rh_icml"]
agents.register_preset(
    "oracle_rh_icml_seed_bonus",
    dataclasses.replace(
        _oracle_rh_icml,
        bonuses=(dataclasses.replace(HYPERSTATE_BONUS, updates_per_iteration=4, buffer_size=100_000),),
        anneal_bonus=False,
    ),
)
agents.register_preset(
    "oracle_rh_icml_seed_ppo",
    dataclasses.replace(
        _oracle_rh_icml,
        ppo=dataclasses.replace(
            _oracle_rh_icml.ppo, num_envs=32, minibatch_unit="envs", advantage_norm="minibatch", value_loss="mse"
        ),
    ),
)
