"""Presets of the turn-around campaign (docs/turnaround.md) that are not rows of the Figure-2 grid.

`oracle_rh_prior20`: `oracle_rh` with its hyper-state RND prior scaled by 20 (the preset: 5, the reference's
belief-oracle value; `oracle_rh_prior10` in bench/fig2_presets.py: 10, the paper's). H2's dose-response
test: prior 10 turned earlier and ran back faster than prior 5 in the forward-first seeds, but seed 2
walked back too slowly with either.
Use with  --import bench/fig2_presets.py bench/turnaround/presets.py
          --config bench/fig2.toml bench/turnaround/prior_20.toml
"""

from __future__ import annotations

import dataclasses

from hyperstate import agents

_oracle_rh = agents.PRESETS["oracle_rh"]
agents.PRESETS["oracle_rh_prior20"] = dataclasses.replace(
    _oracle_rh, bonuses=(dataclasses.replace(_oracle_rh.bonuses[0], prior_scale=20.0),)
)
