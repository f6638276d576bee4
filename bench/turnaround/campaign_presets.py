"""Presets of the turn-around campaign (docs/turnaround.md) that are not rows of the Figure-2 grid.

`oracle_rh_prior20`: `oracle_rh` with its hyper-state RND prior scaled by 20 (H2's dose-response test: the
reference code's 5 never made the turn pay at 2e7 frames, the paper's 10 did in 2 of 3 seeds; seed 2 walked
back too slowly with either). Run 9 ran it from commit e5c5baa, where this file was
bench/turnaround/presets.py and `oracle_rh` still had prior 5 (the preset is the same either way).
Use with  --import bench/fig2_presets.py bench/turnaround/campaign_presets.py  (fig2.toml has a table for the
          former's row)  --config bench/fig2.toml bench/turnaround/prior_20.toml

`oracle_rh_rs`: `oracle_rh` (prior 10) plus `hyperx`'s state bonus r_s on x (H8: more experience far along
the second direction, where its gait is trained). Config: bench/turnaround/oracle_rh_rs.toml.
"""

from __future__ import annotations

import dataclasses

from hyperstate import agents
from hyperstate.agents.presets import STATE_BONUS

_oracle_rh = agents.PRESETS["oracle_rh"]
agents.PRESETS["oracle_rh_prior20"] = dataclasses.replace(
    _oracle_rh, bonuses=(dataclasses.replace(_oracle_rh.bonuses[0], prior_scale=20.0),)
)
agents.PRESETS["oracle_rh_rs"] = dataclasses.replace(_oracle_rh, bonuses=(*_oracle_rh.bonuses, STATE_BONUS))
