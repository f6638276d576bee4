"""What does an agent's *untrained* policy do? How far it moves the cheetah, and how much its actions depend
on the belief, per initialisation seed.

    .venv/bin/python research/turnaround/init_probe.py --agent oracle_rh_icml --seeds 0 1 2 --set ppo.network=reference
    .venv/bin/python research/turnaround/init_probe.py --agent oracle_rh_icml --seeds $(seq 0 9) --json OUT.json

For each seed the agent's networks are built as a training run of that seed builds them, then deployed
on the 20 held-out tasks of `cheetah_dir_sparse` (deterministic and sampled actions): the mean final |x|
and the share of deployments that leave the 5 m zone. On 256 random normalised states it also reports
the policy's mean |action| under the forward belief and the mean |difference| between its actions under
the two certain beliefs (the backward [1, 0] and the forward [0, 1] exact belief; oracle agents only).
"""

from __future__ import annotations

import argparse
import json
import os

os.environ.setdefault("MUJOCO_GL", "disable")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from hyperstate import agents, suite  # noqa: E402
from hyperstate.evaluation.deploy import deploy, evaluation_tasks  # noqa: E402

TASK = "cheetah_dir_sparse"
ZONE = 5.0


def probe(preset: str, seed: int, overrides: dict, tasks: np.ndarray) -> dict:
    agent = agents.make(preset, **overrides)
    env = suite.load(TASK, seed=0, privileged=True)
    agent.build(env.observation_spec(), env.action_spec(), seed, suite.position_keys(TASK))
    row: dict = {"seed": seed}
    for label, deterministic in (("deterministic", True), ("sampled", False)):
        x = deploy(agent, TASK, tasks, deterministic=deterministic).observations["x_displacement"][..., 0]
        row[label] = {"final_abs_x": float(np.abs(x[-1]).mean()), "left_zone": float((np.abs(x).max(0) >= ZONE).mean())}
    if agent.belief.feature_dim == 2:  # the exact belief: [P(backward), P(forward)]
        state = torch.randn(256, agent.state_dim, generator=torch.Generator().manual_seed(0))
        with torch.no_grad():
            backward, forward = (
                agent.model.mean_std(state, torch.tensor([b] * len(state)))[0] for b in ([1.0, 0.0], [0.0, 1.0])
            )
        row["mean_abs_action"] = float(forward.abs().mean())
        row["belief_action_difference"] = float((forward - backward).abs().mean())
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agent", default="oracle_rh_icml", help="a preset")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    parser.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="config overrides (JSON values)")
    parser.add_argument("--json", help="write every row to this file")
    args = parser.parse_args()
    overrides = {}
    for item in args.set:
        name, _, value = item.partition("=")
        try:
            overrides[name] = json.loads(value)
        except json.JSONDecodeError:
            overrides[name] = value
    tasks = evaluation_tasks(TASK, 20)
    rows = []
    for seed in args.seeds:
        row = probe(args.agent, seed, overrides, tasks)
        rows.append(row)
        det, sampled = row["deterministic"], row["sampled"]
        line = (
            f"seed {seed}: deterministic |x_T| {det['final_abs_x']:.2f} m, left the zone {det['left_zone']:.2f}; "
            f"sampled |x_T| {sampled['final_abs_x']:.2f} m, left {sampled['left_zone']:.2f}"
        )
        if "mean_abs_action" in row:
            difference = row["belief_action_difference"]
            line += f"; mean |a| {row['mean_abs_action']:.3f}, |a(forward) - a(backward)| {difference:.3f}"
        print(line, flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"agent": args.agent, "overrides": overrides, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
