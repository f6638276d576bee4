"""Where a cell's files outlive the node that runs it: `--storage`, a folder on any fsspec filesystem.

A Ray cell (evaluation/remote.py) works in a folder of its own node and copies what it writes — its
folder `cells/<cell>/` and its tensorboard folder `tb/<cell>/`, under the same relative paths as in
`--out` (evaluation/grid.py) — to the storage as it goes, checkpoint last. A cell that starts (again, on
any node: after a node died, or on `--resume`) first copies back what the storage holds and resumes from
it. The storage is a local or mounted path by default (then `--out` itself) or a URI such as
`s3://bucket/grids/fig2` or `gs://…` (with `s3fs` or `gcsfs` installed).
"""

from __future__ import annotations

from pathlib import Path

from hyperstate.evaluation import grid

CHECKPOINT = "checkpoint.pt"  # what the trainer writes into its checkpoint folder (the cell's folder)


def _filesystem(storage: str):
    import fsspec

    fs, root = fsspec.core.url_to_fs(str(storage))
    return fs, root.rstrip("/")


def cell_paths(cell: str) -> tuple[str, str]:
    """The two folders of a cell, relative to `--out` (and to the storage)."""
    return f"{grid.CELLS}/{cell}", f"{grid.TENSORBOARD}/{cell}"


def holds_cells(storage: str) -> bool:
    """Whether the storage holds cells already (of an earlier run)."""
    fs, root = _filesystem(storage)
    return fs.exists(f"{root}/{grid.CELLS}") and bool(fs.ls(f"{root}/{grid.CELLS}"))


def clear(storage: str) -> None:
    """Removes every cell from the storage (`--force`)."""
    fs, root = _filesystem(storage)
    for folder in (grid.CELLS, grid.TENSORBOARD):
        if fs.exists(f"{root}/{folder}"):
            fs.rm(f"{root}/{folder}", recursive=True)


class CellStore:
    """One cell's files in the storage, mirrored to and from a local working folder."""

    def __init__(self, storage: str, cell: str):
        self.fs, self.root = _filesystem(storage)
        self.cell = cell
        self._copied: dict[str, tuple[int, int]] = {}  # relative path -> (mtime_ns, size) last pushed or pulled

    def local_files(self, workdir: Path) -> list[Path]:
        """The cell's files under `workdir` in the order they are copied: the record second to last, the
        checkpoint last."""
        files = [
            p
            for folder in cell_paths(self.cell)
            if (workdir / folder).is_dir()
            for p in (workdir / folder).rglob("*")
            if p.is_file() and not p.name.startswith(".")  # temp files being written
        ]
        # The files do not change while they are copied (the cell copies them itself, between iterations),
        # and locally a checkpoint never runs ahead of the record and snapshots written before it. Copying
        # the checkpoint last keeps that in the storage whenever a node dies mid-copy: a resumed cell then
        # starts from a checkpoint whose evaluation points and snapshots are all stored (a record or a
        # snapshot ahead of it is fine: those points are evaluated and saved again, identically).
        last = {grid.RECORD: 1, CHECKPOINT: 2}
        return sorted(files, key=lambda p: (last.get(p.name, 0), str(p)))

    def pull(self, workdir: Path) -> list[str]:
        """Copies the cell's stored files into `workdir`; returns their relative paths."""
        pulled = []
        for folder in cell_paths(self.cell):
            remote = f"{self.root}/{folder}"
            if not self.fs.exists(remote):
                continue
            for path in self.fs.find(remote):
                if path.endswith(".part"):
                    continue  # a copy a dying node left unfinished: its previous version stands
                relative = path[len(self.root) + 1 :]
                local = workdir / relative
                local.parent.mkdir(parents=True, exist_ok=True)
                self.fs.get_file(path, str(local))
                stat = local.stat()
                self._copied[relative] = (stat.st_mtime_ns, stat.st_size)
                pulled.append(relative)
        return pulled

    def push(self, workdir: Path, skip: tuple[str, ...] = ()) -> int:
        """Copies the files of `workdir` that changed since the last push to the storage, each through a
        temporary name (a node dying mid-copy leaves the previous version); returns how many."""
        pushed = 0
        for local in self.local_files(workdir):
            if local.name in skip:
                continue
            relative = str(local.relative_to(workdir))
            stat = local.stat()
            if self._copied.get(relative) == (stat.st_mtime_ns, stat.st_size):
                continue
            remote = f"{self.root}/{relative}"
            self.fs.makedirs(remote.rsplit("/", 1)[0], exist_ok=True)
            self.fs.put_file(str(local), remote + ".part")
            self.fs.mv(remote + ".part", remote)
            self._copied[relative] = (stat.st_mtime_ns, stat.st_size)
            pushed += 1
        return pushed
