"""The shipped agents (zoo/) deploy to the online return of the records they were trained with."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hyperstate.evaluation.provenance import cpu_description
from hyperstate.evaluation.saved import deploy_saved

ROOT = Path(__file__).resolve().parents[1]
ZOO = ROOT / "zoo"
SOURCES = json.loads((ZOO / "sources.json").read_text())


@pytest.mark.parametrize("cell", sorted(SOURCES))
def test_zoo_agent_deploys_to_its_records_online_return(cell, tmp_path):
    folder = ZOO / cell
    recorded = json.loads((folder / "record.json").read_text())
    assert recorded["complete"] and recorded["config"]["ppo"]["network"] == "reference"
    (deployed,) = deploy_saved([folder], tmp_path, None, len(recorded["final"]["online_return_per_task"]), None)
    assert deployed["recorded_online_return"] == recorded["final"]["online_return"]
    got, want = deployed["final"], recorded["final"]
    if SOURCES[cell]["cpu"] == cpu_description():
        # The processor it was trained on: the same floats, task for task.
        assert got["online_return_per_task"] == pytest.approx(want["online_return_per_task"], rel=1e-6, abs=1e-6)
        assert got["correct_direction"] == want["correct_direction"]
    else:
        # Another processor's floats: a 200-step deployment drifts, the strategy does not.
        assert got["online_return"] == pytest.approx(want["online_return"], rel=0.15)
        assert abs(got["correct_direction"] - want["correct_direction"]) <= 0.1
