"""``crowdmpc train`` on a full disk where TensorBoard's event writer, a thread of its own, is what fails."""

from __future__ import annotations

import errno
import os
import threading

import pytest

from pipelines.cli import main
from tests.predictors.samples import write_walk_file


@pytest.fixture(autouse=True)
def _private_dirs(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))
    monkeypatch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path_factory.mktemp("shipped")))


def test_a_full_disk_under_tensorboards_writer_is_one_line_naming_the_run(tmp_path, monkeypatch, capsys):
    """The writer thread printed "Exception in thread Thread-1: Traceback ..." around the CLI's line, which
    said "could not write (No space left on device)", naming nothing: a write's error carries no file."""
    from tensorboard.summary.writer.record_writer import RecordWriter

    def full(self, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(RecordWriter, "write", full)
    printed: list[threading.ExceptHookArgs] = []
    monkeypatch.setattr(threading, "excepthook", printed.append)  # what Python would print
    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    args = ["train", "--model", "vanilla_lstm", "--train", str(data), "--val", str(data), "--epochs", "1"]
    assert main([*args, "--out", str(out), "--name", "walker", "--no-progress"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[-1].startswith(f"crowdmpc train: error: could not write {out} (No space left on device); ")
    assert not [line for line in err if "Traceback" in line or "Exception in thread" in line]
    assert printed == []
    assert threading.excepthook == printed.append  # the hook the run found is back
