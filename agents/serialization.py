"""Agent and checkpoint files that hold data only: loading one never runs code.

Python's pickle calls whatever a file names, so a crafted `agent.pt` could run anything when loaded.
These files are read with `torch.load(weights_only=True)`, which only rebuilds tensors and plain
containers (dict, list, tuple, str, int, float, bool, None). Everything else an agent saves is converted
first by `encode`: a NumPy array becomes its raw bytes (a uint8 tensor) with its dtype and shape, a NumPy
scalar likewise, and any other object is an error at save time (so a checkpoint never silently loses
state). `decode` reverses it exactly, bit for bit.

Files written before this format (a pickle of NumPy arrays) still load: for them, and only them, the
loader allows the few NumPy constructors of plain numeric arrays, and nothing else.
"""

from __future__ import annotations

import os
import pickle
import re
import zipfile
from collections import OrderedDict
from typing import Any

import numpy as np
import torch

from hyperstate.files import replacing

FORMAT = "hyperstate"
VERSION = 1
_ARRAY = "__ndarray__"
_SCALAR = "__npscalar__"


class UnsafeFileError(ValueError):
    """A file that is not plain data (it would need to run code to load), or not a hyperstate file."""


def encode(obj: Any, where: str = "") -> Any:
    """`obj` with every NumPy value replaced by tensors and plain types; raises TypeError on anything else."""
    if obj is None or isinstance(obj, (bool, int, float, str, torch.Tensor)):
        return obj
    if isinstance(obj, np.ndarray):
        return {_ARRAY: _raw(obj, where), "dtype": obj.dtype.str, "shape": list(obj.shape)}
    if isinstance(obj, np.generic):
        array = np.asarray(obj)
        return {_SCALAR: _raw(array, where), "dtype": array.dtype.str}
    if isinstance(obj, dict):
        items = {k: encode(v, f"{where}/{k}") for k, v in obj.items()}
        return OrderedDict(items) if isinstance(obj, OrderedDict) else items
    if isinstance(obj, (list, tuple)):
        values = [encode(v, f"{where}[{i}]") for i, v in enumerate(obj)]
        return values if isinstance(obj, list) else tuple(values)
    raise TypeError(
        f"cannot save {type(obj).__module__}.{type(obj).__qualname__} at {where or '/'}: save tensors, "
        "NumPy arrays and plain Python values"
    )


def _raw(array: np.ndarray, where: str) -> torch.Tensor:
    if array.dtype.hasobject:
        raise TypeError(f"cannot save an object array at {where or '/'}")
    return torch.from_numpy(np.ascontiguousarray(array).reshape(-1).view(np.uint8).copy())


def decode(obj: Any) -> Any:
    """Reverses `encode`."""
    if isinstance(obj, dict):
        if _ARRAY in obj:
            return np.frombuffer(obj[_ARRAY].numpy().tobytes(), np.dtype(obj["dtype"])).reshape(obj["shape"]).copy()
        if _SCALAR in obj:
            return np.frombuffer(obj[_SCALAR].numpy().tobytes(), np.dtype(obj["dtype"]))[0]
        items = {k: decode(v) for k, v in obj.items()}
        return OrderedDict(items) if isinstance(obj, OrderedDict) else items
    if isinstance(obj, list):
        return [decode(v) for v in obj]
    if isinstance(obj, tuple):
        return tuple(decode(v) for v in obj)
    return obj


def save(obj: Any, path: str | os.PathLike, kind: str) -> None:
    """Writes `obj` (a dict of tensors, arrays and plain values) as a hyperstate `kind` file."""
    with replacing(path) as tmp:  # a reader (or a crash) never meets half a file
        torch.save({"format": FORMAT, "version": VERSION, "kind": kind, "data": encode(obj)}, tmp)


def load(path: str | os.PathLike, kind: str) -> Any:
    """Reads a file written by `save` (or by older hyperstate code); never runs code from the file."""
    try:
        raw = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError:
        raw = _load_legacy(path, kind)
    except (RuntimeError, EOFError, zipfile.BadZipFile, ValueError) as e:
        raise UnsafeFileError(f"{path}: not a readable hyperstate {kind} file ({_first_line(e)})") from None
    if isinstance(raw, dict) and raw.get("format") == FORMAT:
        if raw.get("kind") != kind:
            raise UnsafeFileError(f"{path}: a hyperstate {raw.get('kind')} file, not {kind}")
        if not isinstance(raw.get("version"), int) or raw["version"] > VERSION:
            raise UnsafeFileError(f"{path}: format version {raw.get('version')} is newer than this code reads")
        return decode(raw["data"])
    if isinstance(raw, dict) and "modules" in raw and "config" in raw:  # written before the format existed
        return raw
    raise UnsafeFileError(f"{path}: not a hyperstate {kind} file")


# The constructors of plain numeric NumPy arrays and scalars, as older files pickled them.
_LEGACY_NUMPY = [np.ndarray, np.dtype, np._core.multiarray._reconstruct, np._core.multiarray.scalar]
_LEGACY_NUMPY += [type(np.dtype(t)) for t in "?bBhHiIlLqQefdgFD"]


def _load_legacy(path: str | os.PathLike, kind: str) -> Any:
    try:
        with torch.serialization.safe_globals(_LEGACY_NUMPY):
            return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        why = _why_unsafe(e)
        raise UnsafeFileError(f"{path}: refused to load: {why} (a hyperstate {kind} file holds data only)") from None


def _why_unsafe(error: Exception) -> str:
    text = str(error)
    names = re.findall(r"GLOBAL ([\w.]+)", text)
    if names:
        return f"unpickling it would call {', '.join(dict.fromkeys(names))}"
    detail = text.split("WeightsUnpickler error:", 1)[-1]
    lines = [line.strip() for line in detail.splitlines() if line.strip()]
    return f"it is not plain data ({lines[0] if lines else type(error).__name__})"


def _first_line(error: Exception) -> str:
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    return lines[0] if lines else type(error).__name__
