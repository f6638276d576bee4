"""Training stays bit-identical across a refactor: the parameters and logs of short runs, saved and compared.

    .venv/bin/python scripts/bit_identity.py save before.pt      # on the commit before the change
    .venv/bin/python scripts/bit_identity.py compare before.pt   # on the change: exit 1 if anything differs
    .venv/bin/python scripts/bit_identity.py parameters tests/data/parameters_64k.json  # this CPU's entry

`save`/`compare`: trains `PRESETS` (between them every network style, minibatch unit, advantage
normalisation, value loss and bonus training source) on cheetah_dir_sparse for 6,400 frames (8 envs, seed 3,
one torch and one physics thread) and keeps every module state and every iteration's log (times left out).
Floats depend on the processor: compare files made on one machine.

`parameters`: the fixture of tests/test_parameters_64k.py. Trains `hyperx` and `oracle_rh` as the presets
are (16 envs) for 64,000 frames on cheetah_dir_sparse (seed 0, one torch and one physics thread) and adds
this machine's entry (keyed by `machine_key()`) to a JSON file: per module-state value its shape, dtype,
SHA-256, sum and norm, and the numeric fields of every iteration's log. Run it on the commit before a change
to training (as it was on 6fa8130, the commit before the module refactor), so that the test can say "the
same parameters as before". The file stands alone: it needs only `agents.make`, `train` and
`modules_state`, which every commit since the presets has.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from hyperstate import agents  # noqa: E402

PRESETS = ("hyperx", "oracle_rh", "rl2", "varibad_rh", "hyperx_paper", "oracle_paper", "hyperx_icml")  # every strategy
TIMING = ("time", "fps", "wall")
PARAMETER_PRESETS = ("hyperx", "oracle_rh")
PARAMETER_FRAMES = 64_000
PARAMETER_SEED = 0


def machine_key() -> str:
    """The processor (model name, and family, model and stepping: one model name covers several
    generations, which round floats differently) and the vector units torch and numpy dispatch to: runs
    agree bit for bit only where all match."""
    first = {}  # the first processor's block of /proc/cpuinfo
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if not key.strip() and first:
                break
            first.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    model = first.get("model name") or platform.processor() or platform.machine()
    cpuid = ", ".join(f"{k} {first[k]}" for k in ("cpu family", "model", "stepping") if first.get(k))
    if cpuid:
        model += f" ({cpuid})"
    try:
        umath = np._core._multiarray_umath
        simd = " ".join(t for t in umath.__cpu_dispatch__ if umath.__cpu_features__.get(t))
    except AttributeError:
        simd = "unknown"
    return f"{model} / torch {torch.backends.cpu.get_cpu_capability()} / numpy {simd}"


def summarize(value) -> dict | float | int | bool | str | None:
    """A module-state value as JSON: arrays by shape, dtype, SHA-256 of their bytes, float64 sum and norm."""
    if torch.is_tensor(value):
        value = value.detach().cpu().contiguous().numpy()
    if isinstance(value, np.ndarray):
        as_float = value.astype(np.float64)
        return {
            "shape": list(value.shape),
            "dtype": str(value.dtype),
            "sha256": hashlib.sha256(np.ascontiguousarray(value).tobytes()).hexdigest(),
            "sum": float(as_float.sum()),
            "norm": float(np.linalg.norm(as_float.ravel())),
        }
    if isinstance(value, np.generic):
        return value.item()
    return value if isinstance(value, (float, int, bool, str, type(None))) else repr(value)


def parameters_64k(presets: tuple[str, ...] = PARAMETER_PRESETS) -> dict:
    """Per preset: every module-state value summarised, and the numeric fields of the training log."""
    out = {}
    for name in presets:
        torch.manual_seed(PARAMETER_SEED)
        torch.set_num_threads(1)
        agent = agents.make(name, physics_threads=1)
        log = agent.train("cheetah_dir_sparse", PARAMETER_FRAMES, seed=PARAMETER_SEED, progress=False)
        numeric = (int, float, bool, np.number)
        out[name] = {
            "parameters": {path: summarize(v) for path, v in leaves(agent.modules_state())},
            "log": [
                {
                    k: (v.item() if isinstance(v, np.generic) else v)
                    for k, v in e.items()
                    if isinstance(v, numeric) and not any(t in k for t in TIMING)
                }
                for e in log
            ],
        }
    return out


def fingerprint() -> dict:
    out = {}
    for name in PRESETS:
        torch.set_num_threads(1)
        agent = agents.make(name, **{"ppo.num_envs": 8, "physics_threads": 1})
        log = agent.train("cheetah_dir_sparse", 6400, seed=3, progress=False)
        out[name] = agent.modules_state()
        out[f"{name}/log"] = [{k: v for k, v in e.items() if not any(t in k for t in TIMING)} for e in log]
    return out


def leaves(x, path: str = ""):
    if isinstance(x, dict):
        for k, v in x.items():
            yield from leaves(v, f"{path}/{k}")
    elif isinstance(x, (list, tuple)):
        for i, v in enumerate(x):
            yield from leaves(v, f"{path}[{i}]")
    else:
        yield path, x


def equal(a, b) -> bool:
    if torch.is_tensor(a):
        return torch.is_tensor(b) and a.dtype == b.dtype and torch.equal(a, b)
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b, equal_nan=True)
    if isinstance(a, float) and a != a:
        return b != b
    return a == b


def differences(saved: dict, now: dict) -> list[str]:
    a, b = dict(leaves(saved)), dict(leaves(now))
    out = [f"{k}: only in one run" for k in sorted(set(a) ^ set(b))]
    return out + [f"{k}: differs" for k in a if k in b and not equal(a[k], b[k])]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("action", choices=("save", "compare", "parameters"))
    parser.add_argument("path")
    args = parser.parse_args(argv)
    if args.action == "parameters":
        path = Path(args.path)
        entries = json.loads(path.read_text()) if path.exists() else {}
        entries[machine_key()] = parameters_64k()
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(entries, indent=1, sort_keys=True) + "\n")
        print(f"{path}: {', '.join(PARAMETER_PRESETS)} at {PARAMETER_FRAMES:,} frames on {machine_key()!r}")
        return 0
    now = fingerprint()
    if args.action == "save":
        torch.save(now, args.path)
        print(f"saved {len(dict(leaves(now)))} values of {', '.join(PRESETS)} to {args.path}")
        return 0
    found = differences(torch.load(args.path, weights_only=False), now)
    print("\n".join(found[:20]) if found else f"bit-identical: {', '.join(PRESETS)} (parameters and logs)")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
