"""One view of a running grid, drawn by the driver alone.

Each cell writes its state to `cells/<cell>/progress.json` (frames, frames per second, the last online
return, wall time) as it trains; the driver reads those files and shows a line per running cell. On a
terminal that is a live bar per running cell under an overall bar; anywhere else (CI, log files, Ray
logs) it is a plain line per running cell every `PLAIN_EVERY_SECONDS`, and a line when a cell ends. Cells
never draw on the terminal themselves, so parallel workers cannot interleave their output.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import TextIO

from hyperstate.evaluation import grid

PLAIN_EVERY_SECONDS = 60.0
# How often the driver folds the cells' records into OUT/results.json while a grid runs, and how often it
# looks at the cells (progress view, finished cells).
RESULTS_EVERY_SECONDS = 30.0
POLL_SECONDS = 2.0


def read_progress(out: Path, cell: str) -> dict | None:
    try:
        return json.loads((grid.cell_dir(out, cell) / grid.PROGRESS).read_text())
    except (OSError, json.JSONDecodeError):
        return None  # not started, or being replaced right now


def describe(cell: str, state: dict) -> str:
    frames, total = state["frames"], state["total_frames"]
    parts = [f"{cell}  {frames / 1e6:.2f}M/{total / 1e6:.2f}M frames", f"{state['fps']:,.0f} frames/s"]
    if state.get("online_return") is not None:
        parts.append(f"online return {state['online_return']:.1f} (at {state['return_frames'] / 1e6:.2f}M)")
    if state.get("eta_seconds") is not None:
        parts.append(f"ETA {state['eta_seconds'] / 60:.0f} min")
    return "  ".join(parts)


class GridProgress:
    """Polled by the driver while cells run; `enabled=False` shows nothing (--no-progress)."""

    def __init__(self, out: Path, cells: list[str], enabled: bool = True, stream: TextIO | None = None):
        self.out, self.cells, self.enabled = Path(out), list(cells), enabled
        self.stream = stream if stream is not None else sys.stderr
        self.live = enabled and hasattr(self.stream, "isatty") and self.stream.isatty()
        self.finished: set[str] = set()
        self.last_plain = time.monotonic()
        self.bars: dict[str, object] = {}
        self.overall = None
        if self.live:
            from tqdm.auto import tqdm

            self._tqdm = tqdm
            self.overall = tqdm(total=len(cells), desc="grid", unit="cell", position=0, file=self.stream)

    def poll(self) -> None:
        """Reads the running cells' progress and redraws (live) or prints lines when due (plain)."""
        if not self.enabled:
            return
        running = {}
        for cell in self.cells:
            if cell not in self.finished:
                state = read_progress(self.out, cell)
                if state is not None and not state.get("complete"):
                    running[cell] = state
        if self.live:
            self._draw(running)
        elif running and time.monotonic() - self.last_plain >= PLAIN_EVERY_SECONDS:
            self.last_plain = time.monotonic()
            for cell, state in running.items():
                print(f"[grid {len(self.finished)}/{len(self.cells)} done] {describe(cell, state)}", file=self.stream)
            self.stream.flush()

    def cell_done(self, cell: str, failed: bool = False) -> None:
        self.finished.add(cell)
        if not self.enabled:
            return
        state = read_progress(self.out, cell)
        what = "failed" if failed else "done"
        line = f"[grid {len(self.finished)}/{len(self.cells)} done] {cell} {what}"
        if state is not None and state.get("online_return") is not None and not failed:
            line += f": online return {state['online_return']:.1f} after {state['wall_seconds'] / 60:.1f} min"
        if self.live:
            bar = self.bars.pop(cell, None)
            if bar is not None:
                bar.close()
            self.overall.update(1)
            self._tqdm.write(line, file=self.stream)
        else:
            print(line, file=self.stream)
            self.stream.flush()

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()
        if self.overall is not None:
            self.overall.close()

    def _draw(self, running: dict[str, dict]) -> None:
        for cell, state in running.items():
            bar = self.bars.get(cell)
            if bar is None:
                taken = {b.pos for b in self.bars.values()}
                position = next(p for p in range(1, len(self.cells) + 2) if p not in taken and -p not in taken)
                bar = self._tqdm(
                    total=state["total_frames"], desc=cell, unit="frame", unit_scale=True, position=position,
                    leave=False, file=self.stream,
                )  # fmt: skip
                self.bars[cell] = bar
            bar.n = state["frames"]
            postfix = {"fps": f"{state['fps']:,.0f}"}
            if state.get("online_return") is not None:
                postfix["return"] = f"{state['online_return']:.1f}"
            bar.set_postfix(postfix, refresh=False)
            bar.refresh()
