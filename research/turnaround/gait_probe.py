"""Does an agent have the gait its way back needs? Deploy it told the task from the first step.

    .venv/bin/python research/turnaround/gait_probe.py runs/fig2_20m/cells/oracle_rh__cheetah_dir_sparse__s2 [CELL ...]
    .venv/bin/python research/turnaround/gait_probe.py CELL/snapshots/agent_000999936.pt ...   # saved agents work too
    .venv/bin/python research/turnaround/gait_probe.py CELL [CELL ...] --every 2 --json OUT.json --plot OUT.png
    .venv/bin/python research/turnaround/gait_probe.py CELL --import my_components.py   # as the cell's run had it

Failing `oracle_rh` runs turn after a wrong first exit and walk back at ~1 m/s (research/turnaround/notebook.md).
Either the policy has no fast gait in the direction it learned second, or it has one and does not use
it on the way back. This deploys each cell's final agent (`agent.pt`; or each agent file given) on the
20 held-out tasks twice, with deterministic actions: as the harness does, and *told* — its exact-belief
observation replaced by the one-hot of the true direction from the first step, so it never has to guess.
Per direction it prints the online return, the final x and the mean speed towards the rewarded side over
the episode (m/s). A policy with the gait runs the told direction from the start; one without walks.

For an agent with a learned belief (variBAD, task-supervised, RL²'s features) there is no belief
observation to replace: *told* then clamps the belief features the policy sees, from the first step, to
the posterior its own encoder reaches on that direction — the mean final features of the as-trained
deployments of that direction that left the zone (any exit reveals the direction: the far side pays,
the wrong side charges). A direction no deployment left the zone on cannot be told (its row is blank).

`--every N` probes every N-th kept snapshot of each cell (`snapshots/agent_<frames>.pt`) and the final
agent, so the told speeds can be followed through training; `--json` writes every row, `--plot` draws
each cell's told speed in its first direction (the faster one at the end) and its second against frames.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from hyperstate import agents  # noqa: E402
from hyperstate.evaluation import grid  # noqa: E402
from hyperstate.evaluation.deploy import deploy, evaluation_tasks  # noqa: E402
from hyperstate.evaluation.imports import import_modules  # noqa: E402
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


class ToldPosterior:
    """An agent with a learned belief whose policy sees, at every step, the belief features `revealed`
    gives for its task's direction (+1 forward, -1 backward): the posterior it reaches once it knows."""

    def __init__(self, agent, tasks: np.ndarray, revealed: dict[float, np.ndarray]):
        self.agent = agent
        self.features = torch.as_tensor(np.stack([revealed[float(t)] for t in np.asarray(tasks)[:, 0]]))

    def act(self, obs, state=None, deterministic=True, reward=None):
        belief = self.agent.belief
        belief.features = lambda _state: self.features.to(torch.float32)  # shadows the method for this call
        try:
            return self.agent.act(obs, state, deterministic=deterministic, reward=reward)
        finally:
            del belief.features


def revealed_posteriors(deployment, zone: float = 5.0) -> dict[float, np.ndarray]:
    """Per direction (+1.0 / -1.0), the mean belief features at the last step of the deployments of that
    direction that left the zone; directions none left the zone on are missing."""
    x = deployment.observations["x_displacement"][..., 0]  # (T, M)
    left = np.abs(x).max(0) >= zone
    final = deployment.features[-1]  # (M, F)
    out = {}
    for sign in (1.0, -1.0):
        m = (deployment.tasks[:, 0] == sign) & left
        if m.any():
            out[sign] = final[m].mean(0)
    return out


def per_direction(deployment) -> dict[str, dict[str, float]]:
    """Online return, final x and mean speed towards the rewarded side (m/s), per direction."""
    x = deployment.observations["x_displacement"][..., 0]  # (T, M), after each step
    d = deployment.tasks[:, 0]
    seconds = x.shape[0] * CONTROL_TIMESTEP
    out = {}
    for name, sign in (("forward", 1.0), ("backward", -1.0)):
        m = d == sign
        if not m.any():  # a direction the deployment has no task of (an untold one)
            out[name] = {"online_return": None, "final_x": None, "speed": None}
            continue
        out[name] = {
            "online_return": float(deployment.rewards[:, m].sum(0).mean()),
            "final_x": float(x[-1, m].mean()),
            "speed": float((sign * x[-1, m]).mean() / seconds),
        }
    return out


def probes(cell: Path, every: int) -> list[tuple[int | None, Path]]:
    """(frames or None for the final agent, agent file) to probe for one cell folder or agent file."""
    if cell.suffix == ".pt":
        return [(None, cell)]
    found = grid.snapshots_in(cell)[every - 1 :: every] if every > 0 else []
    record = cell / grid.RECORD
    frames = json.loads(record.read_text()).get("frames") if record.exists() else None
    # The harness keeps a snapshot at each evaluation point; when the last one is the final agent, probe it once.
    return [*(f for f in found if f[0] != frames), (frames, cell / "agent.pt")]


def run_name(cell: Path) -> str:
    """'OUT: agent sN' for a cell folder runs/OUT/cells/agent__task__sN (or an agent file in one)."""
    folder = cell
    if cell.suffix == ".pt":
        folder = cell.parent.parent if cell.parent.name == grid.SNAPSHOTS else cell.parent
    parts = folder.name.split("__")
    return f"{folder.parent.parent.name}: {parts[0]} {parts[-1]}"


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = list(dict.fromkeys(r["run"] for r in rows))
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for i, run in enumerate(runs):
        told = [r for r in rows if r["run"] == run and r["deployment"].startswith("told") and r["frames"]]
        if not told:
            continue
        last = told[-1]
        speeds = {k: last[k]["speed"] if last[k]["speed"] is not None else -np.inf for k in ("forward", "backward")}
        first = "forward" if speeds["forward"] >= speeds["backward"] else "backward"
        second = "backward" if first == "forward" else "forward"
        frames = [r["frames"] / 1e6 for r in told]
        colour = f"C{i % 10}"

        def speed(r: dict, direction: str) -> float:
            return np.nan if r[direction]["speed"] is None else r[direction]["speed"]

        ax.plot(frames, [speed(r, first) for r in told], color=colour, lw=1, alpha=0.5)
        ax.plot(
            frames,
            [speed(r, second) for r in told],
            color=colour,
            lw=2,
            ls="--",
            marker="o",
            ms=3,
            label=f"{run} (second: {second})",
        )
    ax.set_xlabel("training frames (M)")
    ax.set_ylabel("speed towards the told direction (m/s)")
    ax.set_title("Told the task from the first step: first direction (thin) and second (dashed)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("cells", type=Path, nargs="+", help="cell folders (their agent.pt) or saved agent files")
    parser.add_argument("--every", type=int, default=0, help="also every N-th kept snapshot of each cell (0: none)")
    parser.add_argument("--json", type=Path, default=None, help="write every row here")
    parser.add_argument("--plot", type=Path, default=None, help="draw told speeds against frames here (--every)")
    parser.add_argument(
        "--labels", nargs="+", default=None, help="one name per cell, in order (default: 'OUT: agent sN')"
    )
    parser.add_argument(
        "--import", dest="imports", nargs="*", default=[], help="files registering the cells' own components"
    )
    args = parser.parse_args()
    import_modules(args.imports)
    torch.set_num_threads(1)
    tasks = evaluation_tasks(TASK, 20)
    if args.labels is not None and len(args.labels) != len(args.cells):
        parser.error(f"--labels names {len(args.labels)} runs for {len(args.cells)} cells")
    labels = args.labels or [run_name(cell) for cell in args.cells]
    rows = []
    print(
        "| run | frames | deployment | R forward | x forward | m/s forward | R backward | x backward | m/s backward |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for cell, label in zip(args.cells, labels, strict=True):
        for frames, path in probes(cell, args.every):
            agent = agents.Agent.load(path)
            name = label if cell.suffix != ".pt" else f"{label} {path.stem}"
            as_trained = deploy(agent, TASK, tasks)
            if agent.config.belief == "oracle":
                told, how_told = Told(agent, tasks), "told the task"
            elif agent.belief.feature_dim > 0:
                revealed = revealed_posteriors(as_trained)
                shown = np.asarray([t in revealed for t in tasks[:, 0]])
                told = ToldPosterior(agent, tasks[shown], revealed) if shown.any() else None
                how_told = "told: revealed posterior"
            else:
                raise SystemExit(f"{path}: the {agent.config.belief!r} belief has no features to tell")
            r = per_direction(as_trained)
            results = [("as trained", r)]
            if told is not None:
                told_tasks = tasks if agent.config.belief == "oracle" else tasks[shown]
                results.append((how_told, per_direction(deploy(told, TASK, told_tasks))))
            for how, r in results:
                rows.append({"run": name, "frames": frames, "deployment": how, **r})
                cells = [
                    f"{v['online_return']:.0f} | {v['final_x']:+.1f} | {v['speed']:.1f}"
                    if v["online_return"] is not None
                    else " | "
                    for v in (r["forward"], r["backward"])
                ]
                print(f"| `{name}` | {frames or '—'} | {how} | {cells[0]} | {cells[1]} |", flush=True)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    if args.plot:
        plot(rows, args.plot)


if __name__ == "__main__":
    main()
