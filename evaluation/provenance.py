"""Where a result comes from: package versions, the git commit of the code, and the processor."""

from __future__ import annotations

import platform
import subprocess
from importlib import metadata
from pathlib import Path


def versions() -> dict:
    """Package versions, the git commit of the code and the processor that produced a result."""
    out = {"python": platform.python_version()}
    for package in ("hyperstate", "torch", "mujoco", "dm-control", "numpy"):
        try:
            out[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            out[package] = None
    try:
        root = Path(__file__).resolve().parents[1]
        out["git_commit"] = (
            subprocess.run(
                ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10
            ).stdout.strip()
            or None
        )
    except (OSError, subprocess.SubprocessError):
        out["git_commit"] = None
    out["cpu"] = cpu_description()
    return out


def cpu_description() -> str:
    """The processor and its widest vector unit: a run's floats, and so its learning curve, depend on them."""
    model, flags = platform.processor() or platform.machine(), set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and value.strip():
                model = value.strip()
            elif key.strip() == "flags":
                flags = set(value.split())
            if flags and model:
                break
    except OSError:
        pass
    vector = next((f for f in ("avx512f", "avx2", "avx", "neon", "asimd") if f in flags), None)
    return f"{model} ({vector})" if vector else model
