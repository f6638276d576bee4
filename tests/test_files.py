"""One atomic writer for every file the packages write (hyperstate.files)."""

from __future__ import annotations

import os
import stat
import threading

import numpy as np
import pytest

from hyperstate.files import replacing, write_bytes_atomic


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "record.json"
    target.write_text("old")
    with pytest.raises(RuntimeError), replacing(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("crash mid-write")
    assert target.read_text() == "old" and os.listdir(tmp_path) == ["record.json"]


def test_concurrent_writers_never_share_a_temporary_and_the_result_is_whole(tmp_path):
    target = tmp_path / "results.json"
    payloads = [bytes([i]) * 200_000 for i in range(8)]
    seen_tmps: list[str] = []

    def write(data: bytes) -> None:
        with replacing(target) as tmp:
            seen_tmps.append(tmp.name)
            tmp.write_bytes(data)

    threads = [threading.Thread(target=write, args=(p,)) for p in payloads]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(set(seen_tmps)) == len(payloads)  # a unique name each
    assert target.read_bytes() in payloads  # one writer's whole file, not a mix
    assert os.listdir(tmp_path) == ["results.json"]
    write_bytes_atomic(target, b"x")
    assert stat.S_IMODE(target.stat().st_mode) == 0o644 and target.read_bytes() == b"x"


def test_agent_and_checkpoint_files_are_written_atomically(tmp_path, monkeypatch):
    import torch

    from hyperstate.agents import serialization

    path = tmp_path / "agent.pt"
    serialization.save({"w": torch.ones(3)}, path, kind="agent")

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(torch, "save", broken)
    with pytest.raises(OSError):
        serialization.save({"w": torch.zeros(3)}, path, kind="agent")
    assert torch.equal(serialization.load(path, kind="agent")["w"], torch.ones(3))
    assert os.listdir(tmp_path) == ["agent.pt"]


def test_json_lines_log_appends_and_stops_at_a_line_cut_short(tmp_path):
    from hyperstate.files import append_json_line, read_json_lines

    log = tmp_path / "log.jsonl"
    assert read_json_lines(log) == []
    append_json_line(log, {"frames": 1, "value": np.float32(0.5)})
    append_json_line(log, {"frames": 2, "value": [1, 2]})
    with log.open("a") as f:
        f.write('{"frames": 3, "val')  # a crash mid-write
    assert read_json_lines(log) == [{"frames": 1, "value": 0.5}, {"frames": 2, "value": [1, 2]}]
