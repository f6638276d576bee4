"""Extra rows of the campaign's Figure-2 grids (research/turnaround/reproduce_fig2.sh and the turn-around grid
script of its time imported this file in every worker).

`oracle_rh_prior5`: `oracle_rh` with its hyper-state RND prior scaled by 5, the reference code's value for
the belief oracle, instead of the preset's 10 (the paper's, and the value that made the turn-around pay
in 2 of 3 seeds at 2e7 frames where 5 did in none: research/turnaround/notebook.md). The grid keeps both, side by side.

`oracle_rh_rs`: the belief oracle with `hyperx`'s bonuses, hyper-state and state RND (r_h + r_s, λ 10 each):
`oracle_rh` plus the state bonus, so that the row differs from `hyperx` only in its belief. Under the
turn-around settings (H16 + H18) it made the turn pay in 2 of 3 seeds by 1e7 frames where `oracle_rh`, with
r_h alone, ran one way (research/turnaround/notebook.md, H19); the paper's oracle has r_h alone, which
`oracle_rh` keeps.
"""

from __future__ import annotations

import dataclasses

from hyperstate import agents

# The campaign's presets were the seed paper's, today the `_paper` ones (their tables in fig2.toml and the
# configs/ overlays are named after the campaign's names, e.g. [oracle_rh]: see research/turnaround/README.md).
_oracle_rh = agents.PRESETS["oracle_rh_paper"]
(STATE_BONUS,) = agents.PRESETS["oracle_rs_paper"].bonuses
agents.register_preset(
    "oracle_rh_prior5",
    dataclasses.replace(_oracle_rh, bonuses=(dataclasses.replace(_oracle_rh.bonuses[0], prior_scale=5.0),)),
)
agents.register_preset("oracle_rh_rs", dataclasses.replace(_oracle_rh, bonuses=(*_oracle_rh.bonuses, STATE_BONUS)))
