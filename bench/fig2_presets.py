"""Extra rows of the Figure-2 grid (bench/reproduce_fig2.sh imports this file in every worker).

`oracle_rh_prior10`: `oracle_rh` with its hyper-state RND prior scaled by 10, the paper's value, instead
of the 5 the reference code uses for the belief oracle. One 20M-frame seed of it turned around where
`oracle_rh` did not (docs/results.md); the grid tests that on three seeds, next to the committed preset.
"""

from __future__ import annotations

import dataclasses

from hyperstate import agents

_oracle_rh = agents.PRESETS["oracle_rh"]
agents.PRESETS["oracle_rh_prior10"] = dataclasses.replace(
    _oracle_rh, bonuses=(dataclasses.replace(_oracle_rh.bonuses[0], prior_scale=10.0),)
)
