"""Deploy saved agents without training: `hyperstate-run --deploy CELL_OR_AGENT.pt [...] --out OUT`.

Each path is a cell folder (holding `agent.pt` and `record.json`: a cell of a grid, or of the `zoo/`) or an
`agent.pt` file. Its agent is deployed on the held-out tasks of its task (or of `--tasks`) exactly as the
harness deploys at the end of training (deterministic actions, then sampled ones, the same tasks and seeds),
and OUT gets one cell per path: record.json (`final` as a trained cell's, an empty `curve`, `deployed_from`
and, from the cell's record, `recorded_online_return`), deployment.npz, and the report (results.json,
summary.csv, figures/ with the behaviour plot). Deploying a cell's final agent reproduces its record's
online return on the processor it was trained on (other processors agree to the float tolerance of the
simulator and the networks, which a long deployment can amplify).
"""

from __future__ import annotations

import json
from pathlib import Path

from hyperstate.evaluation import grid, protocol
from hyperstate.evaluation.deploy import deploy, deployment_metrics, evaluation_tasks


class SavedAgentError(ValueError):
    """A --deploy path that holds no deployable agent; its message names the path."""


def _source(path: Path) -> tuple[Path, dict | None]:
    """(agent file, the cell's record or None)."""
    if path.is_dir():
        agent_file, record_file = path / grid.AGENT, path / grid.RECORD
        if not agent_file.exists():
            raise SavedAgentError(f"--deploy {path}: no {grid.AGENT} in this folder (merged cells keep none)")
        record = json.loads(record_file.read_text()) if record_file.exists() else None
        return agent_file, record
    if not path.exists():
        raise SavedAgentError(f"--deploy {path}: no such file or folder")
    record_file = path.parent / grid.RECORD
    return path, (json.loads(record_file.read_text()) if record_file.exists() else None)


def deploy_saved(
    paths: list[Path], out: Path, tasks: list[str] | None, eval_tasks: int, episodes_per_task: int | None
) -> list[dict]:
    """Deploys every saved agent (on `tasks`, default: each record's task) and writes its cell under `out`;
    returns the records."""
    from hyperstate.evaluation.cell import save_deployment
    from hyperstate.evaluation.provenance import versions
    from hyperstate.files import write_json_atomic

    records = []
    for path in paths:
        agent_file, source = _source(Path(path))
        if source:
            name, seed = source["agent"], source["seed"]
        else:  # only the file: its saved name says the agent ("hyperx seed 0")
            saved = agents_saved_name(agent_file)
            name, _, seed_text = saved.partition(" seed ")
            seed = int(seed_text) if seed_text else 0
        try:
            agent = protocol.load_agent(name, agent_file)
        except (ValueError, TypeError, OSError) as e:
            raise SavedAgentError(f"--deploy {path}: {type(e).__name__}: {e}") from None
        for task in tasks or [source["task"] if source else None]:
            if task is None:
                raise SavedAgentError(f"--deploy {path}: no record.json beside it says its task: pass --tasks")
            held_out = evaluation_tasks(task, eval_tasks)
            final = deploy(agent, task, held_out, episodes_per_task)
            record = {
                "agent": name,
                "task": task,
                "seed": seed,
                "frames": source["frames"] if source else None,
                "trained_on": source.get("trained_on") if source else None,
                "config": protocol.describe(agent),
                "curve": [],
                "final": deployment_metrics(final, task, probe=True),
                "versions": versions(),
                "complete": True,
                "deployed_from": str(path),
            }
            sampled = deploy(agent, task, held_out, episodes_per_task, deterministic=False)
            record["final"]["stochastic"] = deployment_metrics(sampled, task)
            if source and source.get("final") and source["task"] == task:
                record["recorded_online_return"] = source["final"]["online_return"]
            directory = grid.cell_dir(out, grid.record_cell_id(record))
            directory.mkdir(parents=True, exist_ok=True)
            save_deployment(directory, final)
            write_json_atomic(directory / grid.RECORD, record)
            records.append(record)
    return records


def agents_saved_name(agent_file: Path) -> str:
    """The name a hyperstate agent file was saved under ("hyperx seed 0"), or "" for other agents' files."""
    from hyperstate.agents import serialization

    try:
        return str(serialization.load(agent_file, kind="agent").get("name", ""))
    except (serialization.UnsafeFileError, OSError, KeyError):
        return ""


def summary_lines(records: list[dict]) -> list[str]:
    """One line per deployed agent: its online return against its record's, and how it explored."""
    lines = []
    for r in records:
        final = r["final"]
        recorded = r.get("recorded_online_return")
        against = "" if recorded is None else f" (its record: {recorded:.1f})"
        metrics = "  ".join(
            f"{k} {final[k]:.2f}" for k in ("correct_direction", "turned_around", "stuck") if final.get(k) is not None
        )
        lines.append(f"{r['agent']} seed {r['seed']} on {r['task']}: online return {final['online_return']:.1f}"
                     f"{against}  {metrics}")  # fmt: skip
    return lines
