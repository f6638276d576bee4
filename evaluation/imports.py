"""`--import`: the user's modules that register tasks and agents, imported in every worker before its cells.

A .py file is imported under its file's name; a cell on another machine (evaluation/remote.py) gets the
file's source from the driver (`read_import_sources`) and imports a local copy (`materialize_imports`).
"""

from __future__ import annotations

from pathlib import Path

from hyperstate.files import write_bytes_atomic


def read_import_sources(names: tuple[str, ...] | list[str]) -> tuple[tuple[str, str], ...]:
    """(path, source) of every .py file among `--import` names, for cells on other machines."""
    return tuple((name, Path(name).read_text()) for name in names if name.endswith(".py"))


def materialize_imports(imports: tuple[str, ...], sources: tuple[tuple[str, str], ...]) -> tuple[str, ...]:
    """`imports` with each shipped .py file replaced by a copy of its source on this machine.

    The copy keeps the file's name (its module name: what registers the user's tasks and agents) in a
    folder named by the source's hash, so a worker that runs several cells imports the same file again
    (a no-op) and a changed source is never taken for the old one.
    """
    import hashlib
    import tempfile

    shipped = dict(sources)
    local = []
    for name in imports:
        if name not in shipped:
            local.append(name)
            continue
        source = shipped[name]
        digest = hashlib.sha256(source.encode()).hexdigest()[:16]
        path = Path(tempfile.gettempdir()) / "hyperstate-imports" / digest / Path(name).name
        if not path.exists():  # the folder is named by the source's hash: an existing copy is this source
            path.parent.mkdir(parents=True, exist_ok=True)
            write_bytes_atomic(path, source.encode())
        local.append(str(path))
    return tuple(local)


def import_modules(names: tuple[str, ...] | list[str]) -> None:
    """Imports modules by name or .py path (user tasks register themselves with suite on import)."""
    import importlib
    import importlib.util
    import sys

    for name in names:
        if name.endswith(".py"):
            module_name = Path(name).stem
            if module_name in sys.modules:
                # The same file again is a no-op; another module of that name (a file with the same stem, or
                # a library such as `json`) would otherwise be taken silently for this file.
                loaded = getattr(sys.modules[module_name], "__file__", None)
                if loaded is not None and Path(loaded).resolve() == Path(name).resolve():
                    continue
                raise ImportError(
                    f"{name}: a module named {module_name!r} is already imported (from {loaded or 'a built-in'}); "
                    "rename the file"
                )
            spec = importlib.util.spec_from_file_location(module_name, name)
            if spec is None or spec.loader is None:
                raise ImportError(f"cannot import {name}")
            module = importlib.util.module_from_spec(spec)
            sys.modules[module_name] = module
            spec.loader.exec_module(module)
        else:
            importlib.import_module(name)
