"""Brings a finished cell of an older grid up to the current metrics, without retraining.

`evaluation/run.py --resume` calls `upgrade_record` for every cell that is already complete, so resuming a
grid written by older code fills in what it lacks from what the cell saved:
- `final.certainty_equivalent` of a task-aware reference (its `agent.pt`, deployed Bayes-adaptively on
  the same held-out tasks);
- the belief probe per BAMDP step (`final.probe_kl_per_step`, `probe_accuracy_per_step`), refit from the
  final deployment's features and exact beliefs (`deployment.npz`; the probe is seeded, so its aggregate
  scores equal the recorded ones);
- the task's exploration metrics it declares now but did not then (recomputed from `deployment.npz`);
- `final.stochastic`, the deployment with sampled actions (its `agent.pt`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hyperstate import suite
from hyperstate.evaluation import grid, protocol
from hyperstate.evaluation.deploy import (
    certainty_equivalent_metrics,
    deploy,
    deployment_metrics,
    evaluation_tasks,
    exploration_metric_means,
    reads_true_task,
)
from hyperstate.evaluation.probe import belief_quality
from hyperstate.evaluation.report import REFERENCE_AGENT


def upgrade_record(record: dict, directory: Path, episodes_per_task: int | None = None) -> list[str]:
    """Fills in what a complete record lacks, in place; returns the names of what it added."""
    final = record.get("final")
    if not record.get("complete") or final is None:
        return []
    added = []
    npz = directory / grid.DEPLOYMENT
    data = np.load(npz) if npz.exists() else None
    if data is not None and _task_metrics(record, data):
        added.append("task metrics")
    if data is not None and _probe_per_step(record, data):
        added.append("probe per step")
    agent_path = directory / grid.AGENT
    # Only the reference is deployed Bayes-adaptively (see run.py); other agents never get that entry.
    reference = record["agent"] == REFERENCE_AGENT
    needs_agent = "stochastic" not in final or (reference and "certainty_equivalent" not in final)
    if agent_path.exists() and needs_agent:
        import torch

        # The thread count the cell deployed with after training: float sums depend on it, and a sampled
        # deployment amplifies a last-digit difference into another trajectory.
        torch.set_num_threads(int(record.get("config", {}).get("torch_threads", 1)))
        agent = protocol.load_agent(record["agent"], agent_path)
        tasks = evaluation_tasks(record["task"], len(final["online_return_per_task"]))
        if "stochastic" not in final:
            sampled = deploy(agent, record["task"], tasks, episodes_per_task, deterministic=False)
            final["stochastic"] = deployment_metrics(sampled, record["task"])
            added.append("stochastic deployment")
        if reference and "certainty_equivalent" not in final and reads_true_task(agent):
            final["certainty_equivalent"] = certainty_equivalent_metrics(
                agent, record["task"], tasks, episodes_per_task
            )
            added.append("certainty_equivalent")
    return added


def _task_metrics(record: dict, data) -> bool:
    final = record["final"]
    observations = {k.removeprefix("obs_"): data[k] for k in data.files if k.startswith("obs_")}
    means = exploration_metric_means(record["task"], observations, data["rewards"], data["tasks"])
    missing = sorted(set(means or ()) - set(final))
    if not missing:
        return False
    final.update({name: means[name] for name in missing})
    final["exploration_metric_names"] = sorted(means)
    return True


def _probe_per_step(record: dict, data) -> bool:
    final = record["final"]
    if "probe_kl_per_step" in final or "probe_kl" not in final or "obs_belief" not in data.files:
        return False
    # The exact belief when each action was chosen: the prior, then the belief each step ended in.
    after = data["obs_belief"]
    prior = np.broadcast_to(suite.load(record["task"], seed=0).task.prior_belief(), after.shape[1:])
    exact = np.concatenate([prior[None], after[:-1]])
    final.update(belief_quality(data["features"], exact))
    return True
