"""docs/new_task.md's example runs as written: registered from the user's own file, then benchmarked."""

import json
import re
import sys
from pathlib import Path

import numpy as np

from hyperstate import suite

ROOT = Path(__file__).resolve().parents[1]


def test_new_task_example_registers_trains_and_benchmarks(tmp_path):
    text = (ROOT / "docs" / "new_task.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    assert len(code.strip().splitlines()) <= 40
    module = tmp_path / "my_tasks.py"
    module.write_text(code)
    command = re.search(r"```bash\n(.*?)```", text, re.S).group(1).replace("\\\n", " ").split()
    assert command[:2] == [".venv/bin/python", "evaluation/run.py"]
    args = command[2:]
    # A tiny budget instead of the document's, and the example file from where the test wrote it.
    args[args.index("--import") + 1] = str(module)
    args[args.index("--frames") + 1] = "400"
    args[args.index("--out") + 1] = str(tmp_path / "out")
    seeds = args.index("--seeds")
    args[seeds + 1 : seeds + 4] = ["0"]
    config = tmp_path / "tiny.toml"
    config.write_text('[all]\n"ppo.num_envs" = 4\n"ppo.rollout_length" = 50\n"vae.batch_trajectories" = 2\n')
    from hyperstate.evaluation.run import main

    try:
        # Two workers: cells run in spawned processes, which must import the user's file themselves.
        assert main([*args, "--config", str(config), "--eval-tasks", "2", "--workers", "2", "--no-progress"]) == 0
        records = json.loads((tmp_path / "out" / "results.json").read_text())
        assert {r["agent"] for r in records} == {"oracle", "varibad", "task_aware"}
        assert all(r["complete"] and r["task"] == "line_goal_sparse" for r in records)
        # The task itself: pushing toward the goal earns reward and reveals the goal.
        env = suite.load("line_goal_sparse", seed=0, privileged=True)
        step = env.reset()
        goal = step.observation["task"][0]
        rewards = [env.step(np.array([goal])).reward for _ in range(50)]
        assert max(rewards) == 1.0 and env.task.belief.max() == 1.0
    finally:
        if "line_goal_sparse" in suite.TASKS:
            suite.unregister("line_goal_sparse")
        sys.modules.pop("my_tasks", None)
