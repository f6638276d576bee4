"""Training stays bit-identical across a refactor: the parameters and logs of short runs, saved and compared.

    .venv/bin/python scripts/bit_identity.py save before.pt      # on the commit before the change
    .venv/bin/python scripts/bit_identity.py compare before.pt   # on the change: exit 1 if anything differs

Trains `PRESETS` (between them every network style, minibatch unit, advantage normalisation, value
loss and bonus training source) on cheetah_dir_sparse for 6,400 frames (8 envs, seed 3,
one torch and one physics thread) and keeps every module state and every iteration's log (times left out).
Floats depend on the processor: compare files made on one machine.
"""

from __future__ import annotations

import argparse
import os
import sys

os.environ.setdefault("MUJOCO_GL", "disable")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from hyperstate import agents  # noqa: E402

PRESETS = ("hyperx", "oracle_rh", "rl2", "varibad_rh", "hyperx_paper", "oracle_paper", "hyperx_icml")  # every strategy
TIMING = ("time", "fps", "wall")


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
    parser.add_argument("action", choices=("save", "compare"))
    parser.add_argument("path")
    args = parser.parse_args(argv)
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
