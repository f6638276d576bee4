"""Atomic file writes, shared by the three packages: a reader sees the old file or the new one, never a part.

Every writer goes through a temporary file of a unique name beside the target (so concurrent writers never
share one) that replaces the target only once it is complete.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np


@contextlib.contextmanager
def replacing(path: str | os.PathLike) -> Iterator[Path]:
    """Yields a fresh temporary path beside `path`; when the block ends without an error it replaces `path`
    atomically (readable by everyone), else it is removed and `path` is untouched."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)  # mkstemp makes it private; results are for everyone to read
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Writes `data` to `path` atomically (`replacing`)."""
    with replacing(path) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Writes `text` (UTF-8) to `path` atomically (`replacing`)."""
    write_bytes_atomic(path, text.encode())


def write_json_atomic(path: str | os.PathLike, data: Any) -> None:
    """`data` as JSON (NumPy scalars and arrays as numbers and lists), written atomically."""
    write_bytes_atomic(path, json.dumps(data, indent=1, default=_json_default).encode())


def append_json_line(path: str | os.PathLike, data: Any) -> None:
    """Appends `data` as one JSON line to `path` (a log that grows; a crash can cut only its last line)."""
    with Path(path).open("a") as f:
        f.write(json.dumps(data, default=_json_default) + "\n")


def read_json_lines(path: str | os.PathLike) -> list[Any]:
    """The entries of a JSON-lines log (`append_json_line`), none where it does not exist; a line cut short by
    a crash ends it."""
    entries = []
    if Path(path).exists():
        for line in Path(path).read_text().splitlines():
            try:
                entries.append(json.loads(line))
            except json.JSONDecodeError:
                break
    return entries


def save_array_atomic(path: str | os.PathLike, array: np.ndarray) -> None:
    """`array` as a .npy file, written atomically."""
    buffer = io.BytesIO()
    np.save(buffer, array)
    write_bytes_atomic(path, buffer.getvalue())


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
