"""What a stranger's file, a fresh machine and parallel cells cannot break.

Agent and checkpoint files load without running code; saved state survives the data-only format bit for
bit; parallel writers never collide; the install exposes only `hyperstate.*`; the lock is what `make`
installs.
"""

from __future__ import annotations

import ast
import json
import pickle
import re
import subprocess
import sys
import zipfile
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pytest
import torch

from hyperstate import agents, suite
from hyperstate.agents import serialization
from hyperstate.agents.serialization import UnsafeFileError

ROOT = Path(__file__).resolve().parents[1]
TINY = {"ppo.num_envs": 2, "ppo.rollout_length": 20, "ppo.minibatches": 1}


class _OpenOnLoad:
    """Unpickling this calls open(marker, "w"): what a malicious file would do with os.system."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), "w"))


def _crafted_files(tmp_path: Path, marker: Path) -> list[Path]:
    as_torch = tmp_path / "crafted_torch.pt"  # a torch zip whose data names Path.touch
    torch.save({"config": {}, "modules": _OpenOnLoad(marker)}, as_torch)
    files = [as_torch]
    for protocol in (2, pickle.HIGHEST_PROTOCOL):  # bare pickles, as older torch.save wrote them
        files.append(tmp_path / f"crafted_pickle{protocol}.pt")
        files[-1].write_bytes(pickle.dumps({"config": {}, "modules": _OpenOnLoad(marker)}, protocol=protocol))
    return files


def test_crafted_agent_files_run_no_code(tmp_path):
    marker = tmp_path / "code_ran"
    messages = []
    for path in _crafted_files(tmp_path, marker):
        with pytest.raises(UnsafeFileError) as error:
            agents.Agent.load(path)
        messages.append(str(error.value))
        assert messages[-1].startswith(f"{path}: refused to load: ") and "\n" not in messages[-1]
        assert not marker.exists()
    assert all("unpickling it would call io.open" in m for m in messages[:2])
    # The files are real exploits: the unsafe loader would have run them.
    torch.load(tmp_path / "crafted_torch.pt", weights_only=False)
    assert marker.exists()


def test_crafted_checkpoint_runs_no_code_on_resume(tmp_path):
    marker = tmp_path / "code_ran"
    crafted = _crafted_files(tmp_path, marker)[0]
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    crafted.rename(run_dir / "checkpoint.pt")
    agent = agents.make("oracle", **TINY)
    with pytest.raises(UnsafeFileError, match="checkpoint.pt"):
        agent.train("cheetah_dir_sparse", frames=40, seed=0, checkpoint_dir=run_dir, resume=True, progress=False)
    assert not marker.exists()


def test_not_a_hyperstate_file_is_a_one_line_error(tmp_path):
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"\x00not a checkpoint")
    with pytest.raises(UnsafeFileError, match="garbage.pt") as error:
        agents.Agent.load(garbage)
    assert "\n" not in str(error.value)
    other = tmp_path / "tensors.pt"
    torch.save({"weights": torch.zeros(3)}, other)
    with pytest.raises(UnsafeFileError, match="not a hyperstate agent file"):
        agents.Agent.load(other)


def test_saved_agent_is_plain_data_and_acts_the_same(tmp_path):
    agent = agents.make("varibad", **TINY, **{"vae.batch_trajectories": 2})
    agent.train("cheetah_dir_sparse", frames=80, seed=0, progress=False)
    agent.save(tmp_path / "agent.pt")
    # Plain torch, no allowlist: only tensors and Python containers inside.
    raw = torch.load(tmp_path / "agent.pt", weights_only=True)
    assert raw["format"] == "hyperstate" and raw["kind"] == "agent"
    loaded = agents.Agent.load(tmp_path / "agent.pt")
    obs = suite.batch("cheetah_dir_sparse", 3, seed=1).reset().observation
    a1, s1 = agent.act(obs, deterministic=True)
    a2, s2 = loaded.act(obs, deterministic=True)
    np.testing.assert_array_equal(a1, a2)
    np.testing.assert_array_equal(agent.belief_features(s1), loaded.belief_features(s2))


def test_agent_files_from_before_the_format_still_load(tmp_path):
    """Older agent.pt files pickled NumPy arrays; they load through an allowlist of NumPy's array
    constructors only."""
    agent = agents.make("oracle_rh", **TINY)
    agent.train("cheetah_dir_sparse", frames=40, seed=0, progress=False)
    legacy = {
        "name": agent.name,
        "config": agents.config.to_dict(agent.config),
        "obs_spec": {k: (shape, np.dtype(dtype)) for k, (shape, dtype) in agent.obs_spec.items()},
        "action_bounds": agent.action_bounds,
        "position_keys": agent.position_keys,
        "modules": agent.modules_state(),
    }
    torch.save(legacy, tmp_path / "old_agent.pt")
    loaded = agents.Agent.load(tmp_path / "old_agent.pt")
    obs = suite.batch("cheetah_dir_sparse", 2, seed=1, privileged=True).reset().observation
    np.testing.assert_array_equal(agent.act(obs)[0], loaded.act(obs)[0])


def test_encode_decode_is_exact_for_every_saved_kind_of_value():
    rng = np.random.default_rng(0)
    floats = rng.normal(size=(3, 4))
    floats[0, 0] = np.nan
    value = {
        "floats": floats,
        "float32": rng.normal(size=5).astype(np.float32),
        "ints": np.arange(-3, 3, dtype=np.int64),
        "uint32": rng.integers(0, 2**32, size=624, dtype=np.uint32),  # a Mersenne Twister key
        "bools": np.array([True, False]),
        "empty": np.zeros((0, 6)),
        "zero_d": np.array(2.5),
        "scalar": np.float64(1.0) / 3,
        "int_scalar": np.int64(7),
        "big_int": 2**127 + 5,  # PCG64 states are 128-bit Python ints
        "nested": [(1, "a", None), {"x": np.ones(2)}],
        "ordered": OrderedDict(w=torch.arange(3.0)),
        "generator": np.random.default_rng(5).bit_generator.state,
        "legacy_rng": np.random.RandomState(3).get_state(legacy=False),
    }
    back = serialization.decode(serialization.encode(value))
    assert back.keys() == value.keys()
    for key in ("floats", "float32", "ints", "uint32", "bools", "empty", "zero_d"):
        assert back[key].dtype == value[key].dtype and back[key].shape == value[key].shape
        assert back[key].tobytes() == value[key].tobytes()
    assert type(back["scalar"]) is np.float64 and back["scalar"] == value["scalar"]
    assert type(back["int_scalar"]) is np.int64 and back["big_int"] == value["big_int"]
    assert back["nested"][0] == (1, "a", None) and isinstance(back["nested"][0], tuple)
    np.testing.assert_array_equal(back["nested"][1]["x"], np.ones(2))
    assert isinstance(back["ordered"], OrderedDict) and torch.equal(back["ordered"]["w"], torch.arange(3.0))
    rng_back = np.random.default_rng()
    rng_back.bit_generator.state = back["generator"]
    assert rng_back.random() == np.random.default_rng(5).random()
    legacy = np.random.RandomState()
    legacy.set_state(back["legacy_rng"])
    assert legacy.random_sample() == np.random.RandomState(3).random_sample()
    with pytest.raises(TypeError, match="at /thing"):
        serialization.encode({"thing": object()})


def test_loop_batch_snapshot_is_plain_data_and_restores_exactly():
    """LoopBatch (what batches tasks without a fast batch) snapshots its tasks' random generators by state."""
    env = suite.LoopBatch(
        [suite.load("quadruped_goal_sparse", seed=s, episode_length=5) for s in suite.spawn_seeds(0, 2)]
    )
    env.reset()
    action = np.zeros((2, *env.action_spec().shape))
    for _ in range(3):
        env.step(action)
    state = serialization.decode(serialization.encode(env.state_dict()))
    first = [env.step(action) for _ in range(4)]  # crosses an episode end: initial states are drawn
    env.load_state_dict(state)
    again = [env.step(action) for _ in range(4)]
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a.reward, b.reward)
        for key in a.observation:
            np.testing.assert_array_equal(a.observation[key], b.observation[key])


# Parallel writers ------------------------------------------------------------------------------------
_WRITER = """
import sys
from pathlib import Path
from hyperstate.files import write_json_atomic
path, tag = Path(sys.argv[1]), sys.argv[2]
for i in range(300):
    write_json_atomic(path, {"writer": tag, "i": i, "payload": list(range(2000))})
"""


def test_two_processes_writing_one_json_file_never_fail(tmp_path):
    target = tmp_path / "results.json"
    writers = [
        subprocess.Popen([sys.executable, "-c", _WRITER, str(target), tag], stderr=subprocess.PIPE, text=True)
        for tag in ("a", "b")
    ]
    for proc in writers:
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err
    data = json.loads(target.read_text())
    assert data["i"] == 299 and data["writer"] in ("a", "b")
    assert [p.name for p in tmp_path.iterdir()] == ["results.json"]  # no temporary file left behind


def test_a_cell_writes_only_its_own_folder(tmp_path):
    from hyperstate.evaluation.cell import CellSpec, run_cell

    spec = CellSpec("oracle", "cheetah_dir_sparse", 0, 80, 40, 2, None, TINY, str(tmp_path), False, False)
    record = run_cell(spec)
    assert record["complete"]
    written = {p.relative_to(tmp_path).parts[:2] for p in tmp_path.rglob("*") if p.is_file()}
    assert written == {("cells", spec.cell_id), ("tb", spec.cell_id)}
    snapshots = sorted(p.name for p in (spec.directory / "snapshots").iterdir())
    assert snapshots == ["agent_000000040.pt", "agent_000000080.pt"]


# The install ---------------------------------------------------------------------------------------
def _imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_no_code_imports_the_bare_folder_names():
    """Inside the repository `import suite` would still work (the folder is there) and would load a
    second copy of the registry: everything must go through `hyperstate.`."""
    bare = {"suite", "agents", "evaluation"}
    offenders = []
    for folder in ("suite", "agents", "evaluation", "tests", "bench", "research", "scripts", "hyperstate"):
        for path in (ROOT / folder).rglob("*.py"):
            if _imported_modules(path) & bare:
                offenders.append(str(path.relative_to(ROOT)))
    for doc in [ROOT / "README.md", *(ROOT / "docs").glob("*.md")]:
        for block in re.findall(r"```python\n(.*?)```", doc.read_text(), re.S):
            if re.search(r"^\s*(import|from) (suite|agents|evaluation)\b", block, re.M):
                offenders.append(str(doc.relative_to(ROOT)))
    assert offenders == []


def test_the_install_exposes_only_hyperstate(tmp_path):
    probe = (
        "import importlib.util, json; from hyperstate import suite, agents, evaluation; "
        "print(json.dumps({n: importlib.util.find_spec(n) is not None for n in ('suite', 'agents', 'evaluation')}))"
    )
    # From a folder outside the repository: only what the install put on the path.
    proc = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout) == {"suite": False, "agents": False, "evaluation": False}


def test_the_wheel_holds_only_the_hyperstate_package(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "--no-build-isolation", "-q", "-w", tmp_path],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    (wheel,) = tmp_path.glob("hyperstate-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert {n.split("/")[0] for n in names} == {"hyperstate", wheel.name.split("-py")[0] + ".dist-info"}
    for module in ("suite/cheetah_dir.py", "agents/agent.py", "evaluation/run.py", "__init__.py"):
        assert f"hyperstate/{module}" in names


def _normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def test_the_lock_is_what_make_installed():
    """constraints.txt pins every package; the environment the tests run in holds exactly those."""
    locked = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, version = line.split("==")
            locked[_normalise(name)] = version
    # In a fresh interpreter: an imported Ray puts its vendored packages (psutil, colorama) on sys.path.
    listing = subprocess.run(
        [
            sys.executable,
            "-c",
            "import json; from importlib import metadata; "
            "print(json.dumps([[d.metadata['Name'], d.version] for d in metadata.distributions()]))",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    installed = {_normalise(name): version.split("+")[0] for name, version in json.loads(listing.stdout)}
    installed.pop("hyperstate")
    assert installed == locked
    assert locked["torch"] == "2.13.0" and locked["mujoco"] == "3.17.0" and locked["dm-control"] == "1.0.50"


def test_an_imported_file_is_never_mistaken_for_another_module(tmp_path, monkeypatch):
    """`--import x/extras.py` runs that file once; a second file with the same stem, or a file named like a
    library module, is an error instead of being skipped silently (its registrations would never happen)."""
    from hyperstate.evaluation.imports import import_modules

    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "trust_extras.py").write_text("import builtins\nbuiltins.TRUST_EXTRAS_RUNS += 1\n")
    (tmp_path / "json.py").write_text("raise AssertionError('must not run')\n")
    import builtins

    monkeypatch.setattr(builtins, "TRUST_EXTRAS_RUNS", 0, raising=False)
    try:
        import_modules([str(tmp_path / "a" / "trust_extras.py")])
        import_modules([str(tmp_path / "a" / "trust_extras.py"), str(tmp_path / "a" / ".." / "a" / "trust_extras.py")])
        assert builtins.TRUST_EXTRAS_RUNS == 1
        with pytest.raises(ImportError, match=r"named 'trust_extras' is already imported .*a/trust_extras.py"):
            import_modules([str(tmp_path / "b" / "trust_extras.py")])
        with pytest.raises(ImportError, match="'json' is already imported"):
            import_modules([str(tmp_path / "json.py")])
        assert builtins.TRUST_EXTRAS_RUNS == 1
    finally:
        sys.modules.pop("trust_extras", None)
