"""Extra rows of the Figure-2 grid (bench/reproduce_fig2.sh imports this file in every worker).

`oracle_rh_prior5`: `oracle_rh` with its hyper-state RND prior scaled by 5, the reference code's value for
the belief oracle, instead of the preset's 10 (the paper's, and the value that made the turn-around pay
in 2 of 3 seeds at 2e7 frames where 5 did in none: docs/turnaround.md). The grid keeps both, side by side.
"""

from __future__ import annotations

import dataclasses

from hyperstate import agents

_oracle_rh = agents.PRESETS["oracle_rh"]
agents.PRESETS["oracle_rh_prior5"] = dataclasses.replace(
    _oracle_rh, bonuses=(dataclasses.replace(_oracle_rh.bonuses[0], prior_scale=5.0),)
)
