"""The presets are the published agents: field for field the agents of the committed grids' records."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from hyperstate import agents
from hyperstate.agents.config import AgentConfig, from_dict

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"
# Fields added to the config after a committed cell ran, each with the value that reproduces the old code.
ADDED_LATER = {"train_on": "rollout"}


def _flat(data: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in data.items():
        if isinstance(value, dict) and key not in ("params", "belief_params"):
            out.update(_flat(value, f"{prefix}{key}."))
        elif key == "bonuses":
            for i, bonus in enumerate(value):
                out.update(_flat(bonus, f"{prefix}{key}.{i}."))
        else:
            out[f"{prefix}{key}"] = list(value) if isinstance(value, tuple) else value
    return out


def _recorded(folder: str, name: str) -> dict:
    record = json.loads((RESULTS / folder / "cells" / f"{name}__cheetah_dir_sparse__s0" / "record.json").read_text())
    return record["config"]


@pytest.mark.parametrize(
    "folder,name",
    [("fig2_turnaround", name) for name in agents.GRID_PRESETS]
    + [("fig2_icml", "hyperx_icml"), ("fig2_icml", "oracle_rh_icml")],
)
def test_preset_is_the_agent_of_the_committed_record(folder, name):
    recorded = _flat(agents.agent_settings(_recorded(folder, name)))
    preset = _flat(json.loads(json.dumps(agents.agent_settings(agents.make(name).config))))
    missing = {k for k in preset if k not in recorded}
    assert {k.rsplit(".", 1)[-1] for k in missing} <= set(ADDED_LATER)
    assert all(preset[k] == ADDED_LATER[k.rsplit(".", 1)[-1]] for k in missing)
    assert {k: preset.get(k) for k in recorded} == recorded
    # ... and the record loads back into that very config.
    loaded = from_dict(AgentConfig, _recorded(folder, name))
    assert agents.agent_settings(loaded) == agents.agent_settings(agents.make(name).config)


def test_paper_presets_are_the_seed_papers_settings():
    for name in agents.GRID_PRESETS:
        validated, paper = agents.get_preset(name), agents.get_preset(f"{name}_paper")
        assert (paper.belief, [b.input for b in paper.bonuses]) == (
            validated.belief,
            [b.input for b in validated.bonuses],
        )
        p = paper.ppo
        assert (p.network, p.minibatch_unit, p.advantage_norm, p.value_loss) == ("cleanrl", "envs", "minibatch", "mse")
        assert (p.lr_anneal_frames, p.sampled_action_cost, p.lr) == (None, 0.0, 7e-4)
        assert all((b.weight, b.buffer_size, b.updates_per_iteration) == (10.0, 10_000, 1) for b in paper.bonuses)
        # Nothing else differs: the belief, VAE and bonus architectures are the same in both families.
        assert dataclasses.replace(paper, ppo=validated.ppo, bonuses=validated.bonuses) == validated
    assert agents.get_preset("oracle_rh").bonuses[0].weight == 20.0
    assert agents.get_preset("hyperx").bonuses[0].weight == 10.0


def test_meta_learners_outside_the_grid_share_its_ppo_and_network():
    grid_ppo = agents.get_preset("hyperx").ppo
    for name in ("ppo", "task_supervised", "oracle_ensemble_rh"):
        assert agents.get_preset(name).ppo == grid_ppo, name
    # RL²'s GRU is trained through the policy's loss: whole env sequences per minibatch (transitions are
    # refused for it), at its own learning rate.
    assert agents.get_preset("rl2").ppo == dataclasses.replace(grid_ppo, minibatch_unit="envs", lr=3e-4)
    ensemble = agents.get_preset("oracle_ensemble_rh").bonuses[0]
    assert (ensemble.buffer_size, ensemble.updates_per_iteration) == (100_000, 4)


def test_runtime_fields_are_not_agent_settings():
    config = agents.make("hyperx", physics_threads=3, torch_threads=2, checkpoint_every=5).config
    assert agents.agent_settings(config) == agents.agent_settings(agents.make("hyperx").config)
    assert set(agents.RUNTIME_FIELDS) <= {f.name for f in dataclasses.fields(AgentConfig)}
    assert agents.agent_settings(agents.make("hyperx", **{"ppo.lr": 1e-3}).config) != agents.agent_settings(config)


@pytest.mark.parametrize(
    "field,value,message",
    [
        ("ppo.lr", -1.0, "ppo.lr must be positive"),
        ("ppo.num_envs", 0, "ppo.num_envs must be positive"),
        ("ppo.gamma", 1.5, r"ppo.gamma must be in \[0, 1\]"),
        ("ppo.entropy_coef", -0.1, "ppo.entropy_coef must be >= 0"),
        ("vae.latent_dim", 0, "vae.latent_dim must be positive"),
        ("bonuses.0.buffer_size", 0, "buffer_size must be positive"),
        ("physics_threads", -1, "physics_threads must be >= 0"),
    ],
)
def test_numeric_fields_are_range_checked_when_the_config_is_built(field, value, message):
    with pytest.raises(ValueError, match=message):
        agents.make("hyperx", **{field: value})


def test_a_budget_beyond_the_fixed_learning_rate_horizon_is_refused():
    config = agents.get_preset("hyperx")
    agents.check_budget(config, 50_000_000)
    with pytest.raises(ValueError, match="outlasts ppo.lr_anneal_frames"):
        agents.check_budget(config, 50_000_001)
    agents.check_budget(agents.get_preset("hyperx_paper"), 10**9)  # annealed over the budget, whatever it is
    assert agents.budget_dependence(config) is None
    assert "lr_anneal_frames" in agents.budget_dependence(agents.get_preset("hyperx_paper"))
    icml = dataclasses.replace(agents.get_preset("hyperx_icml"), ppo=config.ppo)
    assert "bonus_anneal_frames" in agents.budget_dependence(icml)


def test_merging_compares_agent_settings_not_runtime_fields_or_fields_added_since():
    """New seeds of a committed grid merge into it: physics threads and fields added to the config after the
    committed cells ran (at their reproducing value) are no difference; a real setting is."""
    from hyperstate.agents.config import to_dict
    from hyperstate.evaluation.merge import config_differences

    committed = _recorded("fig2_turnaround", "hyperx")  # physics_threads 1, no bonuses.i.train_on
    assert config_differences(committed, to_dict(agents.make("hyperx").config)) == []
    assert config_differences(committed, to_dict(agents.make("hyperx", physics_threads=2).config)) == []
    changed = config_differences(committed, to_dict(agents.make("hyperx", **{"ppo.lr": 1e-3}).config))
    assert changed == ["ppo.lr: 0.0007 != 0.001"]


def _wilson(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    p = k / n
    centre, half = (p + z * z / (2 * n)) / (1 + z * z / n), z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return centre - half / (1 + z * z / n), centre + half / (1 + z * z / n)


def test_summary_counts_the_seeds_whose_turn_pays_with_a_wilson_interval():
    """The committed grid's records, read again: the share of seeds whose turn pays (`correct_direction`
    ≥ 0.9 and wrong-first tasks earning) next to the mean, so a high mean cannot hide a one-way runner."""
    from hyperstate.evaluation.cell import load_records
    from hyperstate.evaluation.report import summary_rows

    rows = {r["agent"]: r for r in summary_rows(load_records(RESULTS / "fig2_turnaround"))}
    solved = {agent: rows[agent]["success_seeds"] for agent in agents.GRID_PRESETS}
    assert solved == {"hyperx": 3, "oracle_rh": 3, "varibad_rh": 1, "oracle_rs": 1, "oracle": 0, "varibad": 0,
                      "task_aware": 3}  # fmt: skip
    for agent, k in solved.items():
        low, high = _wilson(k, 3)
        assert rows[agent]["success_ci95_low"] == pytest.approx(low, abs=1e-9)
        assert rows[agent]["success_ci95_high"] == pytest.approx(high, abs=1e-9)
    # oracle_rs's mean passes "≥ 450" with 2 of its 3 seeds one-way: the share says so.
    assert rows["oracle_rs"]["online_return_mean"] > 450 and rows["oracle_rs"]["success_share"] == pytest.approx(1 / 3)
