"""Does a belief-oracle agent have the gait its way back needs? Deploy it told the task from the first step.

    .venv/bin/python bench/gait_probe.py runs/fig2_20m/cells/oracle_rh__cheetah_dir_sparse__s2 [CELL ...]
    .venv/bin/python bench/gait_probe.py CELL/snapshots/agent_000999936.pt ...   # saved agents work too

Failing `oracle_rh` runs turn after a wrong first exit and walk back at ~1 m/s (docs/turnaround.md).
Either the policy has no fast gait in the direction it learned second, or it has one and does not use
it on the way back. This deploys each cell's final agent (`agent.pt`; or each agent file given) on the
20 held-out tasks twice, with deterministic actions: as the harness does, and *told* — its exact-belief
observation replaced by the one-hot of the true direction from the first step, so it never has to guess.
Per direction it prints the online return, the final x and the mean speed towards the rewarded side over
the episode (m/s). A policy with the gait runs the told direction from the start; one without walks.
Only for agents whose belief reads the task's `belief` observation (the oracle).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from hyperstate import agents  # noqa: E402
from hyperstate.evaluation.deploy import deploy, evaluation_tasks  # noqa: E402
from hyperstate.suite.cheetah_dir import CONTROL_TIMESTEP  # noqa: E402

TASK = "cheetah_dir_sparse"


class Told:
    """An agent whose exact-belief observation is the truth: [P(backward), P(forward)] one-hot on d."""

    def __init__(self, agent, tasks: np.ndarray):
        self.agent = agent
        forward = np.asarray(tasks)[:, 0] > 0
        self.truth = np.stack([~forward, forward], axis=1).astype(np.float64)

    def act(self, obs, state=None, deterministic=True, reward=None):
        obs = {**obs, "belief": self.truth.astype(obs["belief"].dtype)}
        return self.agent.act(obs, state, deterministic=deterministic, reward=reward)


def per_direction(deployment) -> dict[str, dict[str, float]]:
    """Online return, final x and mean speed towards the rewarded side (m/s), per direction."""
    x = deployment.observations["x_displacement"][..., 0]  # (T, M), after each step
    d = deployment.tasks[:, 0]
    seconds = x.shape[0] * CONTROL_TIMESTEP
    out = {}
    for name, sign in (("forward", 1.0), ("backward", -1.0)):
        m = d == sign
        out[name] = {
            "online_return": float(deployment.rewards[:, m].sum(0).mean()),
            "final_x": float(x[-1, m].mean()),
            "speed": float((sign * x[-1, m]).mean() / seconds),
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("cells", type=Path, nargs="+", help="cell folders (their agent.pt) or saved agent files")
    args = parser.parse_args()
    torch.set_num_threads(1)
    tasks = evaluation_tasks(TASK, 20)
    print("| run | deployment | R forward | x forward | m/s forward | R backward | x backward | m/s backward |")
    print("|---|---|---|---|---|---|---|---|")
    for cell in args.cells:
        agent = agents.Agent.load(cell if cell.suffix == ".pt" else cell / "agent.pt")
        if "belief" not in agent.obs_spec or agent.config.belief != "oracle":
            raise SystemExit(f"{cell}: not a belief-oracle agent (belief {agent.config.belief!r})")
        name = cell.name if cell.suffix != ".pt" else f"{cell.parent.parent.name} {cell.stem}"
        for label, deployed in (("as trained", agent), ("told the task", Told(agent, tasks))):
            r = per_direction(deploy(deployed, TASK, tasks))
            f, b = r["forward"], r["backward"]
            print(
                f"| `{name}` | {label} | {f['online_return']:.0f} | {f['final_x']:+.1f} | {f['speed']:.1f} "
                f"| {b['online_return']:.0f} | {b['final_x']:+.1f} | {b['speed']:.1f} |"
            )


if __name__ == "__main__":
    main()
