"""docs/new_task.md's example runs as written: registered from the user's own file, then benchmarked."""

import csv
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

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


def _agent_doc_blocks() -> tuple[list[str], list[list[str]]]:
    text = (ROOT / "docs" / "new_agent.md").read_text()
    code = re.findall(r"```python\n(.*?)```", text, re.S)
    commands = [c.replace("\\\n", " ").split() for c in re.findall(r"```bash\n(.*?)```", text, re.S)]
    return code, commands


def _tiny(args: list[str], module: Path, out: Path, config: Path) -> list[str]:
    args = list(args)
    args[args.index("--import") + 1] = str(module)
    args[args.index("--frames") + 1] = "512"
    args[args.index("--out") + 1] = str(out)
    seeds = args.index("--seeds")
    args[seeds + 1 : seeds + 4] = ["0"]
    if "--config" in args:
        args[args.index("--config") + 1] = str(config)
    else:
        args += ["--config", str(config)]
    return [*args, "--eval-tasks", "2", "--eval-every", "256", "--no-progress"]


TINY_PRESET = '"ppo.num_envs" = 4\n"ppo.rollout_length" = 64\n'


def test_user_bonus_example_registers_and_benchmarks(tmp_path):
    from hyperstate.evaluation.run import main

    (code, _), (command, _) = _agent_doc_blocks()
    assert len(code.strip().splitlines()) <= 40
    module = tmp_path / "my_bonus.py"
    module.write_text(code)
    config = tmp_path / "tiny.toml"
    config.write_text(f'[all]\n{TINY_PRESET}[oracle_count]\n"bonuses.0.params.bin_width" = 1.0\n')
    assert command[:2] == [".venv/bin/python", "evaluation/run.py"]
    try:
        assert main(_tiny(command[2:], module, tmp_path / "out", config)) == 0
        records = json.loads((tmp_path / "out" / "results.json").read_text())
        assert {r["agent"] for r in records} == {"oracle_count", "oracle_rh", "task_aware"}
        count = next(r for r in records if r["agent"] == "oracle_count")
        assert count["config"]["bonuses"][0] == {**count["config"]["bonuses"][0], "kind": "count"}
        assert count["config"]["bonuses"][0]["params"] == {"bin_width": 1.0}  # the --config table reached it
        assert count["complete"] and [p["frames"] for p in count["curve"]] == [256, 512]
        assert "reward_share" in count["curve"][0]  # the harness treats it as any bonus
        # The bonus itself: fewer visits, larger bonus; a saved agent carries its counts.
        from hyperstate import agents

        agent = agents.Agent.load(tmp_path / "out" / "cells" / "oracle_count__cheetah_dir_sparse__s0" / "agent.pt")
        (bonus,) = agent.bonuses
        assert bonus.counts.sum() == 512 and bonus.counts[bonus.bins // 2 - 3 : bonus.bins // 2 + 3].sum() > 0
        with pytest.raises(ValueError, match="bin_width > 0 only"):
            agents.make("oracle_count", **{"bonuses.0.params.bin_widht": 1.0}).check_task("cheetah_dir_sparse")
        # The research told-the-task probe loads such a cell with the same --import, and only with it.
        cell = tmp_path / "out" / "cells" / "oracle_count__cheetah_dir_sparse__s0"
        probe = [sys.executable, str(ROOT / "research" / "turnaround" / "gait_probe.py"), str(cell)]
        env = {**os.environ, "MUJOCO_GL": "disable"}
        told = subprocess.run([*probe, "--import", str(module)], capture_output=True, text=True, env=env, cwd=ROOT)
        assert told.returncode == 0, told.stderr
        assert "| told the task |" in told.stdout and "out: oracle_count s0" in told.stdout
        blind = subprocess.run(probe, capture_output=True, text=True, env=env, cwd=ROOT)
        assert blind.returncode != 0 and "count" in blind.stderr
    finally:
        from hyperstate import agents
        from hyperstate.agents import bonuses as bonus_registry

        if "oracle_count" in agents.PRESETS:
            agents.unregister_preset("oracle_count")
        if "count" in bonus_registry.list_bonuses():
            bonus_registry.unregister_bonus("count")
        sys.modules.pop("my_bonus", None)


def test_external_agent_example_benchmarks_next_to_oracle(tmp_path):
    from hyperstate.evaluation import protocol
    from hyperstate.evaluation.run import main

    (_, code), (_, command) = _agent_doc_blocks()
    assert len(code.strip().splitlines()) <= 60
    module = tmp_path / "my_agent.py"
    module.write_text(code)
    config = tmp_path / "my_agents.toml"
    config.write_text(f"[sb3_ppo]\nn_steps = 128\nbatch_size = 64\n[oracle]\n{TINY_PRESET}[task_aware]\n{TINY_PRESET}")
    args = _tiny(command[2:], module, tmp_path / "out", config)
    try:
        # Two workers: spawned processes import the user's file themselves.
        assert main([*args, "--workers", "2"]) == 0
        records = json.loads((tmp_path / "out" / "results.json").read_text())
        assert {r["agent"] for r in records} == {"sb3_ppo", "oracle", "task_aware"}
        sb3 = next(r for r in records if r["agent"] == "sb3_ppo")
        assert sb3["complete"] and [p["frames"] for p in sb3["curve"]] == [256, 512]
        assert len(sb3["final"]["online_return_per_task"]) == 2 and "left_zone" in sb3["final"]
        rows = list(csv.DictReader((tmp_path / "out" / "summary.csv").open()))
        assert {r["agent"] for r in rows} == {"sb3_ppo", "oracle", "task_aware"}
        assert next(r for r in rows if r["agent"] == "sb3_ppo")["regret"] != ""
        # Its saved agent reloads through its own loader and acts on the harness's batched observations.
        saved = tmp_path / "out" / "cells" / "sb3_ppo__cheetah_dir_sparse__s0" / "agent.pt"
        agent = protocol.load_agent("sb3_ppo", saved)
        obs = suite.batch("cheetah_dir_sparse", 3, seed=0, privileged=True).reset().observation
        action, state = agent.act(obs)
        assert action.shape == (3, 6) and state is None
        # Resuming the finished grid keeps it.
        assert main([*args, "--resume"]) == 0
    finally:
        if "sb3_ppo" in protocol.agent_names():
            protocol.unregister_agent("sb3_ppo")
        sys.modules.pop("my_agent", None)


DOC_PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
MARKER = re.compile(r"<!-- (run: (?P<test>tests/\S+\.py::\w+)|not run(: .*)?) -->")


@pytest.mark.parametrize("page", DOC_PAGES, ids=lambda p: p.name)
def test_every_code_block_runs_in_a_test_or_is_marked_as_not_run(page):
    """A code block in README or docs is preceded by `<!-- run: tests/FILE.py::TEST -->`, naming the test
    that runs it, or by `<!-- not run: why -->`."""
    lines = page.read_text().splitlines()
    inside, blocks = False, 0
    for i, line in enumerate(lines):
        if not line.startswith("```"):
            continue
        if not inside:
            blocks += 1
            marker = MARKER.fullmatch(lines[i - 1].strip()) if i else None
            assert marker, f"{page.name}:{i + 1}: a code block without a run / not-run marker"
            if marker.group("test"):
                path, name = marker.group("test").split("::")
                assert re.search(rf"^def {name}\(", (ROOT / path).read_text(), re.M), f"{page.name}:{i + 1}"
        inside = not inside
    assert not inside, f"{page.name}: an unclosed code block"


def test_readme_is_a_short_entry_point_and_links_only_inside_the_repository():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    for target in re.findall(r"\]\(([^)]+)\)", text):
        assert not target.startswith(("http:", "https:")), target
        assert (ROOT / target).exists(), target


def test_readme_quickstart_runs_as_written(tmp_path):
    text = (ROOT / "README.md").read_text()
    code = re.search(r"## Quickstart.*?```python\n(.*?)```", text, re.S).group(1)
    namespace: dict = {}
    exec(compile(code, "README.md", "exec"), namespace)
    assert namespace["action"].shape == (4, 6) and namespace["out"].reward.shape == (4,)
    block = re.search(r"## Quickstart.*?```bash\n(.*?)```", text, re.S).group(1).replace("\\\n", " ")
    train, deploy = [line.split("#")[0].split() for line in block.strip().splitlines()]
    assert train[0] == deploy[0] == ".venv/bin/hyperstate-run"
    from hyperstate.evaluation.run import build_grid, main, parse_args

    # The training command as written is a valid grid (its budget is hours; the harness's own tests train).
    args = parse_args(train[1:])
    names, _ = build_grid(args)
    assert names == ["hyperx", "oracle_rh", "varibad", "task_aware"] and args.frames == 20_000_000
    out = tmp_path / "deployed"
    deploy[deploy.index("--out") + 1] = str(out)
    deploy[deploy.index("--deploy") + 1] = str(ROOT / deploy[deploy.index("--deploy") + 1])
    assert main([*deploy[1:], "--eval-tasks", "2"]) == 0
    record = json.loads(next((out / "cells").glob("*/record.json")).read_text())
    assert record["agent"] == "hyperx" and record["curve"] == [] and record["recorded_online_return"] > 800


def test_architecture_page_shows_the_drawn_diagram_of_modules_that_exist_and_the_layers_hold(tmp_path):
    """docs/architecture.md: scripts/architecture_diagram.py draws its diagram, every module the
    diagram or the page names exists, and the packages import one way (suite ← agents ← evaluation)."""
    import ast
    import importlib.util

    spec = importlib.util.spec_from_file_location("architecture_diagram", ROOT / "scripts" / "architecture_diagram.py")
    diagram = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(diagram)
    drawn = diagram.draw(tmp_path / "architecture.png")
    assert drawn.stat().st_size > 20_000
    page = (ROOT / "docs" / "architecture.md").read_text()
    assert "](figures/architecture.png)" in page and (ROOT / "docs" / "figures" / "architecture.png").exists()
    named = set(diagram.modules_named()) | set(
        re.findall(r"`((?:suite|agents|evaluation|hyperstate|scripts|tests)/[\w/]*\.?\w*)`", page)
    )
    assert len(named) >= 12
    missing = [n for n in named if not (ROOT / n).exists()]
    assert not missing, missing
    assert "architecture.md" in (ROOT / "mkdocs.yml").read_text()

    forbidden = {
        "suite": ("agents", "evaluation"),
        "agents": ("evaluation",),
        "hyperstate": ("suite", "agents", "evaluation"),
    }
    for package, above in forbidden.items():
        for path in (ROOT / package).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                names = []
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.module:
                    names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
                for name in names:
                    parts = name.split(".")
                    layer = parts[1] if parts[0] == "hyperstate" and len(parts) > 1 else None
                    assert layer not in above, f"{path.relative_to(ROOT)} imports {name}"


def test_readme_results_table_is_the_one_the_report_writes_from_the_committed_grids():
    """The README's tasks × agents table is, character for character, what `hyperstate-report --table`
    writes from the committed grids its command names, so a re-merged grid cannot leave it stale."""
    from hyperstate.evaluation.cross_task import results_table

    text = (ROOT / "README.md").read_text()
    table = re.search(r"<!-- results-table -->\n(.*?)<!-- /results-table -->", text, re.S).group(1)
    command = re.search(r"```bash\n(\.venv/bin/hyperstate-report .*?)```", text, re.S).group(1).replace("\\\n", " ")
    args = command.split()[1:]
    grids = [ROOT / a for a in args[: args.index("--out")]]
    link = args[args.index("--table-link") + 1].strip('"')
    assert grids and all((g / "summary.csv").exists() for g in grids), grids
    assert table == results_table(grids, link=link, say=lambda _: None)
    committed = ROOT / args[args.index("--table") + 1]
    assert committed.read_text() == table


def test_readme_cross_task_numbers_are_the_committed_reports():
    """Every IQM and probability of improvement the README quotes (two decimals, with its interval where
    given) is the committed cross-task CSV's, so that a re-run report cannot leave the prose stale."""
    text = (ROOT / "README.md").read_text()
    paragraph = re.search(r"The same command writes the cross-task report.*?\n\n", text, re.S).group(0)
    paragraph = " ".join(paragraph.split())
    with open(ROOT / "docs" / "results" / "cross_task" / "cross_task.csv") as f:
        rows = {(r["statistic"], r["agent"]): r for r in csv.DictReader(f)}
    number = r"(-?\d\.\d\d)(?: \((-?\d\.\d\d)–(-?\d\.\d\d)\))?"
    quoted = []
    for first, second, *values in re.findall(rf"P\(`(\w+)` > `(\w+)`\) {number}", paragraph):
        quoted.append((("probability_of_improvement", f"{first}>{second}"), values))
    without_pairs = re.sub(rf"P\(`\w+` > `\w+`\) {number}", "", paragraph)
    for names, *values in re.findall(rf"((?:`\w+`(?: and |, )?)+) {number}", without_pairs):
        quoted += [(("iqm", name), values) for name in re.findall(r"`(\w+)`", names)]
    assert len(quoted) >= 8, quoted
    for key, (value, low, high) in quoted:
        row = rows[key]
        for text_value, column in ((value, "value"), (low, "ci_low"), (high, "ci_high")):
            if text_value:
                assert abs(float(text_value) - float(row[column])) <= 0.005 + 1e-9, (key, column, text_value)


RESULTS_PAGES = sorted((ROOT / "docs" / "results").glob("*.md"))
TASK_TABLE = re.compile(r"<!-- task-table: (?P<args>[^>]*?) -->\n\n(?P<table>.*?)\n<!-- /task-table -->", re.S)


@pytest.mark.parametrize("page", RESULTS_PAGES, ids=lambda p: p.name)
def test_results_pages_tables_are_what_page_table_prints_from_their_grids(page):
    """A results page's per-agent table (between `<!-- task-table: GRID METRIC ... -->` markers) is exactly
    what research/catalogue/page_table.py prints from the committed grid, so no number in it is typed by
    hand or left stale by a re-merge."""
    from hyperstate.evaluation.cross_task import task_table

    for match in TASK_TABLE.finditer(page.read_text()):
        grid, *metrics = match.group("args").split()
        decimals = [int(m.split("=")[1]) for m in metrics if m.startswith("--decimals=")] or [1]
        share = "--share" in metrics
        metrics = [m for m in metrics if not m.startswith("--")]
        assert (ROOT / grid / "cells").is_dir(), grid
        table = task_table(ROOT / grid, metrics, decimals[0], share=share, say=lambda _: None)
        assert match.group("table") == table, (page.name, grid)


def test_the_results_pages_hold_task_tables():
    marked = [p.name for p in RESULTS_PAGES if TASK_TABLE.search(p.read_text())]
    assert {
        "point_treasure_sparse.md",
        "point_robot_sparse.md",
        "mountain_treasure_k8_sparse.md",
        "cheetah_dir_sparse.md",
    } <= set(marked)


def test_page_table_update_rewrites_a_stale_table_from_its_grid(tmp_path):
    """`research/catalogue/page_table.py --update PAGE` puts back what the grid gives in place of a stale
    table, leaving the rest of the page as it was."""
    page = ROOT / "docs" / "results" / "cheetah_dir_sparse.md"
    text = page.read_text()
    match = TASK_TABLE.search(text)
    stale = text.replace(match.group("table"), match.group("table").replace("`hyperx`", "`hyperx` 0"), 1)
    assert stale != text
    copy = tmp_path / "page.md"
    copy.write_text(stale)
    proc = subprocess.run(
        [sys.executable, str(ROOT / "research" / "catalogue" / "page_table.py"), "--update", str(copy)],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "1 table(s) changed" in proc.stdout
    assert copy.read_text() == text
