"""How strongly does a hyper-state RND bonus point along x, against how much it moves with the belief?

    .venv/bin/python research/turnaround/bonus_x_probe.py CELL/snapshots/agent_002000000.pt [AGENT ...] \
        [--json OUT.json]

Deploys each saved agent on the 20 held-out tasks of `cheetah_dir_sparse` (deterministic actions, as the
harness) and evaluates its RND bonus on the deployments' own hyper-states twice: as they were (the bonus
through the episode, which under a learned belief moves with the latent at every step), and with the
x-position moved to fixed values, every other input as deployed. A bonus that steers towards the zone's
borders grows with |x| by much more than it varies along the deployment at the agent's own x.
Medians over all steps of all deployments; each ratio is to the median bonus at the deployed x.
"""

from __future__ import annotations

import argparse
import json
import os

os.environ.setdefault("MUJOCO_GL", "disable")

import numpy as np  # noqa: E402

from hyperstate.agents import Agent  # noqa: E402
from hyperstate.evaluation.deploy import deploy, evaluation_tasks  # noqa: E402

TASK = "cheetah_dir_sparse"
POSITIONS = (-20.0, -10.0, -5.0, 0.0, 5.0, 10.0, 20.0)
STEPS = (0, 10, 50, 199)


def probe(path: str, tasks: np.ndarray) -> dict:
    agent = Agent.load(path)
    deployment = deploy(agent, TASK, tasks)
    obs, features = deployment.observations, deployment.features  # (T, M, ...), after each step
    steps, m = features.shape[:2]
    flat = {k: v.reshape(steps * m, *v.shape[2:]) for k, v in obs.items()}
    flat_features = features.reshape(steps * m, -1)
    values = agent.bonus_values(flat, flat_features)
    rnd = [name for name in values if "rnd" in name]
    if not rnd:
        raise SystemExit(f"{path}: no RND bonus to probe (bonuses: {sorted(values)})")
    name = rnd[0]
    deployed = values[name].reshape(steps, m)
    reference = float(np.median(deployed))
    at_x = {}
    for x in POSITIONS:
        moved = {**flat, "x_displacement": np.full_like(flat["x_displacement"], x)}
        at_x[x] = float(np.median(agent.bonus_values(moved, flat_features)[name])) / reference
    x = obs["x_displacement"][..., 0]
    return {
        "agent": path,
        "bonus": name,
        "deployed_x_range": [float(x.min()), float(x.max())],
        "median_bonus_deployed": reference,
        "deployed_over_time": {str(t): float(np.median(deployed[t])) / reference for t in STEPS if t < steps},
        "deployed_10_90": [float(v) / reference for v in np.percentile(deployed, [10, 90])],
        "at_x": {f"{x:+g}": r for x, r in at_x.items()},
        "belief_features_std_over_time": float(features.std(0).mean()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("agents", nargs="+", help="saved agent files (snapshots/agent_*.pt, agent.pt)")
    parser.add_argument("--json", help="write every row to this file")
    args = parser.parse_args()
    tasks = evaluation_tasks(TASK, 20)
    rows = []
    for path in args.agents:
        row = probe(path, tasks)
        rows.append(row)
        over_time = ", ".join(f"t={t} {r:.2g}" for t, r in row["deployed_over_time"].items())
        at_x = ", ".join(f"x={x} {r:.3g}" for x, r in row["at_x"].items())
        (lo, hi), (p10, p90) = row["deployed_x_range"], row["deployed_10_90"]
        print(f"{path}\n  {row['bonus']}, deployed x {lo:+.1f}..{hi:+.1f}")
        print(f"  along the deployments (÷ median): {over_time}; 10-90 % {p10:.2g}..{p90:.2g}")
        print(f"  x moved, belief as deployed (÷ median): {at_x}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
