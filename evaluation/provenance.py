"""Where a result comes from: package versions, the git commit of the code, and the processor."""

from __future__ import annotations

import platform
import shlex
import subprocess
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

from hyperstate.files import append_json_line, read_json_lines


def versions() -> dict:
    """Package versions, the git commit of the code and the processor that produced a result."""
    out = {"python": platform.python_version()}
    for package in ("hyperstate", "torch", "mujoco", "dm-control", "numpy"):
        try:
            out[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            out[package] = None
    out["git_commit"] = git_commit()
    out["cpu"] = cpu_description()
    out["cpu_id"] = cpu_identification()
    return out


def git_commit() -> str | None:
    """The commit of this checkout's code (None outside a git checkout)."""
    try:
        root = Path(__file__).resolve().parents[1]
        return (
            subprocess.run(
                ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10
            ).stdout.strip()
            or None
        )
    except (OSError, subprocess.SubprocessError):
        return None


def record_start(path: Path, command: list[str]) -> dict:
    """Appends one invocation to the JSON-lines file `path`: its command line, the code's commit, the processor
    and the start time (UTC). Returns the entry, which `record_end` completes."""
    entry = {
        "command": shlex.join(command),
        "git_commit": git_commit(),
        "cpu": cpu_description(),
        "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
    append_json_line(path, entry)
    return entry


def record_end(path: Path, entry: dict, wall_seconds: float, failed_cells: int) -> None:
    """Appends the end of the invocation `entry` (from `record_start`) to `path`: the same command and start,
    the end time, the wall time and how many cells failed. A killed run leaves its start line only."""
    end = datetime.now(timezone.utc).isoformat(timespec="seconds")
    ended = {"ended": end, "wall_seconds": round(wall_seconds, 1), "failed_cells": failed_cells}
    append_json_line(path, {**entry, **ended})


def read_commands(path: Path) -> list[str]:
    """The distinct command lines recorded in `path`, in order (none where it does not exist; a line cut short
    by a crash ends it)."""
    return list(dict.fromkeys(entry["command"] for entry in read_json_lines(path)))


def cpu_description() -> str:
    """The processor and its widest vector unit: a run's floats, and so its learning curve, depend on them."""
    first = _first_processor()
    model = first.get("model name") or platform.processor() or platform.machine()
    flags = set(first.get("flags", "").split())
    vector = next((f for f in ("avx512f", "avx2", "avx", "neon", "asimd") if f in flags), None)
    return f"{model} ({vector})" if vector else model


def cpu_identification(cpuinfo: str | None = None) -> str | None:
    """The first processor's family, model and stepping ("family 25, model 17, stepping 1") in the text
    `cpuinfo` (default: /proc/cpuinfo): one model name covers several generations, which can round floats
    differently. None where the text has none."""
    first = _first_processor(cpuinfo)
    names = {"cpu family": "family", "model": "model", "stepping": "stepping"}
    parts = [f"{short} {first[key]}" for key, short in names.items() if first.get(key)]
    return ", ".join(parts) or None


def _first_processor(cpuinfo: str | None = None) -> dict[str, str]:
    """The first processor's block of `cpuinfo` (default: /proc/cpuinfo; empty where it cannot be read)."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text()
        except OSError:
            return {}
    first: dict[str, str] = {}
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        if not key.strip() and first:
            break  # the end of the first processor's block
        first.setdefault(key.strip(), value.strip())
    return first
