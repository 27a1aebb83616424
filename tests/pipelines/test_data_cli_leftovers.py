"""What ``crowdmpc data`` leaves where it fails, and where its outputs go."""

import os
import sys
import types

import pytest

from pipelines.errors import PipelineError
from pipelines.experiments.sweep_folder import check_sweep_directory
from predictors import locking
from tests.cli_calls import run_cli as run
from tests.predictors.samples import write_tiny_ewap


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))


def _synthesize_failing(monkeypatch):
    """A synthesize stopped half way through its scenes (Ctrl-C)."""

    def synthesize(out_path, *_args, **_options):
        out_path.write_text("half the scenes\n")
        raise KeyboardInterrupt

    monkeypatch.setitem(
        sys.modules, "pipelines.experiments.synth", types.SimpleNamespace(synthesize=synthesize)
    )


def test_a_failed_synth_leaves_the_folder_it_found_as_it_was(monkeypatch, tmp_path, capsys):
    """A synth stopped in a folder that existed left its lock there (only the folders it made went), and a
    sweep --out then refused that folder as one holding files. A lock a successful run left stays."""
    _synthesize_failing(monkeypatch)
    folder = tmp_path / "runs"
    folder.mkdir()
    argv = ["data", "synth", "--out", str(folder / "s.ndjson"), "--episodes", "1", "--humans", "2"]
    code, _, err = run(capsys, *argv, "--seed", "0")
    assert code == 130 and err.strip().splitlines()[-1] == "crowdmpc data synth: interrupted"
    assert os.listdir(folder) == []
    check_sweep_directory(folder)  # refuses nothing
    earlier = folder / ".s.ndjson.synth.lock"  # of a synth that finished
    earlier.write_text("")
    assert run(capsys, *argv, "--seed", "1")[0] == 130
    assert os.listdir(folder) == [earlier.name]
    made = tmp_path / "new" / "deeper"  # folders it made go with it, as before
    code, _, _ = run(capsys, "data", "synth", "--out", str(made / "s.ndjson"), *argv[4:], "--seed", "0")
    assert code == 130 and os.listdir(tmp_path) == ["runs"]


def test_a_lock_removed_before_it_was_taken_is_taken_anew(tmp_path, monkeypatch):
    """A run that opened a lock just before a failed run removed it, and locked it just after, held a file
    no newcomer opens: both ran. The lock is taken anew, as the file its path names."""
    lock = tmp_path / ".x.lock"
    real_flock = locking.fcntl.flock
    removed: list[bool] = []

    def flock(fd, operation):
        if not removed:  # the failed run's removal, between this run's open and its lock
            removed.append(True)
            lock.unlink()
        real_flock(fd, operation)

    monkeypatch.setattr(locking.fcntl, "flock", flock)
    with locking.locked(lock, "test"):
        assert removed and lock.is_file()
        newcomer = os.open(lock, os.O_WRONLY)
        try:
            with pytest.raises(BlockingIOError):  # the file a newcomer opens is the one held
                real_flock(newcomer, locking.fcntl.LOCK_EX | locking.fcntl.LOCK_NB)
        finally:
            os.close(newcomer)


def test_a_failed_prepare_leaves_no_lock_nor_folder_it_made(tmp_path, capsys):
    """A prepare of an obsmat.txt with no rows left its .NAME.prepare.lock beside --out, and the folders it
    had made to hold that lock: a sweep --out then refused the folder it was in. A lock a finished prepare
    left stays, as before."""
    raw = write_tiny_ewap(tmp_path / "data")
    obsmat = raw / "seq_eth" / "obsmat.txt"
    rows = obsmat.read_text()
    obsmat.write_text("")
    runs = tmp_path / "runs"
    runs.mkdir()
    for out in (runs / "prepared", runs / "new" / "deeper" / "prepared"):
        code, _, err = run(capsys, "data", "prepare", "--raw", str(raw), "--out", str(out), "--no-tags")
        assert code == 2 and f"{obsmat}: no annotation rows" in err
        assert os.listdir(runs) == []
    check_sweep_directory(runs)  # refuses nothing
    obsmat.write_text(rows)
    argv = ["data", "prepare", "--raw", str(raw), "--out", str(runs / "prepared"), "--no-tags", "--no-check"]
    assert run(capsys, *argv)[0] == 0
    obsmat.write_text("")
    assert run(capsys, *argv)[0] == 2
    assert sorted(os.listdir(runs)) == [".prepared.prepare.lock", "prepared"]


def test_a_folder_holding_only_a_finished_commands_lock_takes_a_new_output(tmp_path, capsys):
    """A finished data synth leaves its hidden .NAME.synth.lock in its folder by design, which `rm DIR/*`
    skips: sweep --out and data prepare --out then refused the folder that held nothing else as one holding
    files. A lock no process holds is no output; one a running command holds still makes the folder taken."""
    folder = tmp_path / "synth"
    folder.mkdir()
    lock = folder / ".orca.ndjson.synth.lock"
    lock.write_text("")
    raw = write_tiny_ewap(tmp_path / "data")
    argv = ["data", "prepare", "--raw", str(raw), "--out", str(folder), "--no-tags", "--no-check"]
    with locking.locked(lock, "test"):  # a synth that runs
        with pytest.raises(PipelineError, match="holds files but no sweep"):
            check_sweep_directory(folder)
        code, _, err = run(capsys, *argv)
        assert code == 2 and "holds files but no prepared data" in err
    check_sweep_directory(folder)  # refuses nothing
    assert run(capsys, *argv)[0] == 0
    assert (folder / "manifest.json").is_file()
