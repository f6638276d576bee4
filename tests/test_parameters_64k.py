"""A 64,000-frame `hyperx` and `oracle_rh` run gives the same parameters as before the module refactor.

tests/data/parameters_64k.json was written by `scripts/bit_identity.py parameters` on 6fa8130 (the commit
before the refactor), one entry per machine: per module-state value its shape, dtype, SHA-256, sum and norm,
and every iteration's log. Floats depend on the processor and its vector units, so:
- on a machine with an entry (same model name, cpu family, model and stepping, and torch/numpy vector
  units), every value's bytes and every log number must be equal: training is bit-identical;
- elsewhere the run is compared with an entry for what does not depend on rounding (the module states'
  names, shapes and dtypes, their integer and scalar values, the log's fields and frames) and for scale only
  (the median relative difference of the float values' norms is under 5 %: a rounding difference gives about
  0.1-0.3 % after 64k frames, measured with ATEN_CPU_CAPABILITY=default against the AVX-512 entry).
  Add an entry for such a machine by running the script on 6fa8130 there (docs/evaluation.md says how).
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "tests" / "data" / "parameters_64k.json"


def load_script():
    spec = importlib.util.spec_from_file_location("bit_identity", ROOT / "scripts" / "bit_identity.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def runs():
    script = load_script()
    entries = json.loads(FIXTURE.read_text())
    key = script.machine_key()
    return key, entries, script.parameters_64k()


def structure(entry: dict) -> dict:
    """What rounding cannot change: names, shapes, dtypes, integer arrays' bytes, scalars, log fields, frames."""
    params = {
        path: (
            (v["shape"], v["dtype"], None if v["dtype"].startswith("float") else v["sha256"])
            if isinstance(v, dict)
            else (v if not isinstance(v, float) else "float")
        )
        for path, v in entry["parameters"].items()
    }
    log = [(sorted(e), e["frames"], e["iteration"]) for e in entry["log"]]
    return {"parameters": params, "log": log}


def median_norm_difference(saved: dict, now: dict) -> float:
    rel = [
        abs(saved[p]["norm"] - now[p]["norm"]) / max(abs(saved[p]["norm"]), 1e-12)
        for p, v in saved.items()
        if isinstance(v, dict) and v["dtype"].startswith("float")
    ]
    return float(np.median(rel))


@pytest.mark.parametrize("preset", ["hyperx", "oracle_rh"])
def test_64k_frames_give_the_parameters_of_before_the_refactor(runs, preset):
    key, entries, now = runs
    assert now[preset]["log"][-1]["frames"] >= 64_000
    if key in entries:
        saved = entries[key][preset]
        differing = [p for p, v in saved["parameters"].items() if now[preset]["parameters"].get(p) != v]
        assert set(saved["parameters"]) == set(now[preset]["parameters"])
        assert not differing, f"{len(differing)} module-state values differ, e.g. {differing[:3]}"
        assert now[preset]["log"] == saved["log"]
    else:
        saved = next(iter(entries.values()))[preset]
        assert structure(now[preset]) == structure(saved)
        assert median_norm_difference(saved["parameters"], now[preset]["parameters"]) < 0.05


def test_the_fixture_is_what_the_script_writes(runs):
    """The fixture's entries hold both presets, every leaf summarised, 20 iterations of 3,200 frames."""
    _, entries, now = runs
    assert entries
    for entry in entries.values():
        for preset in ("hyperx", "oracle_rh"):
            assert set(entry[preset]) == {"parameters", "log"}
            assert [e["frames"] for e in entry[preset]["log"]] == [e["frames"] for e in now[preset]["log"]]
            arrays = [v for v in entry[preset]["parameters"].values() if isinstance(v, dict)]
            assert arrays and all(len(v["sha256"]) == 64 and v["norm"] >= 0 for v in arrays)
