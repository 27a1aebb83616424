"""Outputs that survive a power loss: every writer that renames a temporary over its output syncs the
temporary before the rename and the output's folder after it (predictors.durable.replace_durably). A rename
alone is whole after a kill, but a power loss could put it on disk before the data it names (an empty
table.md, NAME.pt or manifest) or lose it (the output as it was, though the command said it wrote it)."""

from __future__ import annotations

import os
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from tests.predictors.samples import write_tiny_ewap, write_walk_file


class DiskJournal:
    """The fsyncs (by the inode synced) and the renames (by the name renamed onto) of a call, in order."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.events: list[tuple[str, object]] = []
        fsync, replace, rename = os.fsync, os.replace, os.rename

        def synced(fd: int) -> None:
            info = os.fstat(fd)
            self.events.append(("sync", (info.st_dev, info.st_ino)))
            fsync(fd)

        def renamed(real):
            def move(source, target, *args, **kwargs):
                real(source, target, *args, **kwargs)
                self.events.append(("rename", Path(os.fspath(target)).resolve()))

            return move

        monkeypatch.setattr(os, "fsync", synced)
        monkeypatch.setattr(os, "replace", renamed(replace))
        monkeypatch.setattr(os, "rename", renamed(rename))

    def check_durable(self, path: Path) -> None:
        """``path`` was last renamed into place with its data synced before and its folder synced after."""
        path = path.resolve()
        renames = [i for i, event in enumerate(self.events) if event == ("rename", path)]
        assert renames, f"{path.name} was not renamed into place"
        last = renames[-1]
        inode = lambda p: (p.stat().st_dev, p.stat().st_ino)  # noqa: E731
        before = [what for kind, what in self.events[:last] if kind == "sync"]
        after = [what for kind, what in self.events[last + 1 :] if kind == "sync"]
        assert inode(path) in before, f"{path.name}'s data was not synced before its rename"
        assert inode(path.parent) in after, f"{path.name}'s folder was not synced after its rename"


@pytest.fixture
def disk(monkeypatch, tmp_path_factory) -> DiskJournal:
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))
    return DiskJournal(monkeypatch)


def test_a_json_output_and_a_figure(disk, tmp_path):
    """simulate's, compare's, review's and calibrate's --json, train's metrics and settings (write_output,
    replace_file), and every plot (save_figure)."""
    from pipelines.commands import write_output
    from pipelines.whole_files import save_figure

    write_output(tmp_path / "out.json", "{}\n", "--json")
    save_figure(tmp_path / "plot.png", lambda name: Path(name).write_bytes(b"png"))
    disk.check_durable(tmp_path / "out.json")
    disk.check_durable(tmp_path / "plot.png")


def test_a_sweeps_report(disk, tmp_path):
    """table.md, cells.csv, episodes.csv and the plots, renamed from the staging folder."""
    from pipelines.experiments.cells import get_experiment
    from pipelines.experiments.report import write_report
    from tests.pipelines.test_small_fixes import EPISODES, _records

    table2 = get_experiment("table2")
    cells = [c for c in table2.cells() if c.n_humans == 5]
    report = write_report(tmp_path, table2, cells, _records(table2, {(c.method, 5): EPISODES for c in cells}))
    assert {"table.md", "cells.csv", "episodes.csv"} <= {p.name for p in report.files}
    for path in report.files:
        disk.check_durable(path)


def test_sweep_json_a_kept_recording_and_a_recording(disk, tmp_path):
    from pipelines.experiments.log import write_whole
    from tests.pipelines.mcap_episode import record_episode

    write_whole(tmp_path / "sweep.json", b"{}\n")
    disk.check_durable(tmp_path / "sweep.json")
    recorded = record_episode(tmp_path, steps=2)
    disk.check_durable(Path(recorded.path))


def test_the_zoos_manifest_its_copies_and_calibrates_journal(disk, tmp_path):
    from pipelines.commands.calibrate_store import _write_journal
    from predictors.manifest import write_manifest
    from predictors.zoo_edit import _replace_with_link

    disk.check_durable(write_manifest({}, tmp_path))
    (tmp_path / "w.pt").write_bytes(b"weights")
    _replace_with_link(tmp_path / "w.pt", tmp_path / "NAME.pt")
    disk.check_durable(tmp_path / "NAME.pt")
    journal, fd = _write_journal(tmp_path / "calibrations.json", [], None)
    os.close(fd)
    disk.check_durable(journal)


def test_data_prepare_and_data_synth(disk, tmp_path, capsys, monkeypatch):
    """Each prepared file and its manifest; synth's data (written by write_ndjson, renamed into --out) and
    its provenance."""
    from pipelines.cli import main
    from predictors.data.prepare import prepare_ewap
    from predictors.data.trajnet_scenes import write_ndjson

    out = tmp_path / "prepared"
    prepare_ewap(write_tiny_ewap(tmp_path / "data"), out, categorize_scenes=False, log=lambda msg: None)
    prepared = [path for path in sorted(out.rglob("*")) if path.is_file()]
    assert len(prepared) > 3
    for path in prepared:
        disk.check_durable(path)
    write_ndjson(tmp_path / "scenes.ndjson", [], np.zeros((0, 4)))
    disk.check_durable(tmp_path / "scenes.ndjson")

    def synthesize(path, *_args, **_options):
        write_ndjson(path, [], np.zeros((0, 4)))
        return {}

    monkeypatch.setitem(
        sys.modules, "pipelines.experiments.synth", types.SimpleNamespace(synthesize=synthesize)
    )
    synth = tmp_path / "synth" / "s.ndjson"
    argv = ["data", "synth", "--out", str(synth), "--episodes", "1", "--humans", "2", "--seed", "0"]
    assert main([*argv, "--no-progress"]) == 0
    capsys.readouterr()
    disk.check_durable(synth)
    disk.check_durable(synth.with_name("s.synth.json"))


def test_a_trainings_outputs(disk, tmp_path, capsys):
    """NAME.pt and NAME.json moved into --out, its metrics and settings."""
    from pipelines.cli import main

    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    args = ["train", "--model", "vanilla_lstm", "--train", str(data), "--val", str(data), "--name", "walker"]
    assert main([*args, "--epochs", "1", "--out", str(out), "--no-progress"]) == 0
    capsys.readouterr()
    for name in ("walker.pt", "walker.json", "walker.metrics.json"):
        disk.check_durable(out / name)


@pytest.mark.parametrize("manifest_written", [True, False], ids=["removed", "put-back"])
def test_a_zoo_removes_renames(disk, tmp_path, monkeypatch, manifest_written):
    """zoo remove hides the entry's files before its manifest drops the entry, and puts them back when the
    manifest cannot be written: each set of renames was unsynced, so a power loss could undo them after
    the manifest's rename (files no entry names) or after the command's refusal (an entry without files).
    The zoo's folder is synced after the hiding renames, before the manifest's, and after the put-back."""
    from predictors import zoo_edit, zoo_remove
    from tests.predictors.test_zoo_guards import copy_pair

    user = tmp_path / "user"
    zoo_edit.add_to_zoo(
        copy_pair(tmp_path / "run"), name="mine", protocol="p", training_data={}, metrics={}, directory=user
    )
    folder = (user.stat().st_dev, user.stat().st_ino)
    disk.events.clear()
    if not manifest_written:

        def full_disk(*_args, **_kwargs):
            raise OSError(28, "No space left on device")

        monkeypatch.setattr(zoo_remove, "write_manifest", full_disk)
        with pytest.raises(OSError):
            zoo_remove.remove_from_zoo("mine", user)
        renames = [i for i, (kind, _) in enumerate(disk.events) if kind == "rename"]
        put_back = {disk.events[i][1] for i in renames[-2:]}
        assert put_back == {(user / "mine.pt").resolve(), (user / "mine.json").resolve()}
        assert ("sync", folder) in disk.events[renames[-1] + 1 :], "the put-back was not synced"
        assert (user / "mine.pt").is_file() and (user / "mine.json").is_file()
        return
    zoo_remove.remove_from_zoo("mine", user)
    renames = [i for i, (kind, _) in enumerate(disk.events) if kind == "rename"]
    hidden, manifest = renames[-2], renames[-1]
    assert (
        str(disk.events[hidden][1]).endswith(".removed") and disk.events[manifest][1].name == "manifest.json"
    )
    assert ("sync", folder) in disk.events[hidden + 1 : manifest], "the hiding renames were not synced"


def _failing_fsync(monkeypatch, file_errno: int | None, folder_errno: int) -> None:
    """fsync refused with ``folder_errno`` on a folder and ``file_errno`` (None: synced) on a file."""
    import stat

    fsync = os.fsync

    def refused(fd: int) -> None:
        code = folder_errno if stat.S_ISDIR(os.fstat(fd).st_mode) else file_errno
        if code is not None:
            raise OSError(code, os.strerror(code))
        fsync(fd)

    monkeypatch.setattr(os, "fsync", refused)


@pytest.mark.parametrize("errno_name", ["EINVAL", "EOPNOTSUPP"])
def test_a_file_system_that_does_not_sync_still_gets_its_outputs(tmp_path, monkeypatch, errno_name):
    """A file system whose fsync says EINVAL (some FUSE and network ones) failed every rename of an output in
    a traceback since the syncs were added, though the data was written as before them."""
    import errno

    from pipelines.cli import main

    _failing_fsync(monkeypatch, getattr(errno, errno_name), errno.EINVAL)
    out = tmp_path / "prepared"
    argv = ["data", "prepare", "--raw", str(write_tiny_ewap(tmp_path / "data")), "--out", str(out)]
    assert main(argv) == 0
    assert (out / "manifest.json").is_file()


def test_a_files_data_the_disk_did_not_take_ends_in_one_line(tmp_path, monkeypatch, capsys):
    """EIO when a file's data is synced is a write that failed: the command ends in one line naming the file,
    where it ended in a traceback, and nothing is renamed under the output's name."""
    import errno

    from pipelines.cli import main

    _failing_fsync(monkeypatch, errno.EIO, errno.EIO)
    out = tmp_path / "prepared"
    argv = ["data", "prepare", "--raw", str(write_tiny_ewap(tmp_path / "data")), "--out", str(out)]
    assert main(argv) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()[-1:]
    assert "could not write " in line and "(Input/output error: its data did not reach the disk)" in line
    assert not (out / "manifest.json").exists()


def test_a_failed_sync_in_data_prepare_names_the_output_not_its_staging_file(tmp_path, monkeypatch, capsys):
    """The line named prepare's staging file (.prepared.prepare-PID.tmp/train/.biwi_eth.ndjson.PID.tmp),
    removed before it was read, not the output under the --out the user gave."""
    import errno

    from pipelines.cli import main
    from predictors.data import prepare

    _failing_fsync(monkeypatch, errno.EIO, errno.EIO)
    raw = write_tiny_ewap(tmp_path / "data")
    monkeypatch.chdir(tmp_path)
    assert main(["data", "prepare", "--raw", str(raw), "--out", "prepared"]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        "crowdmpc data prepare: error: could not write prepared/train/biwi_eth.ndjson (Input/output error: "
        "its data did not reach the disk); check the disk or its mount (dmesg) and run the command again"
    )
    # the files' syncs at the install (staging/NAME), and a copy's across file systems (NAME.part)
    staging, out = tmp_path / ".prepared.prepare-7.tmp", tmp_path / "prepared"
    for failed in (staging / "val" / "biwi_hotel.ndjson", out / "val" / "biwi_hotel.ndjson.part"):
        exc = prepare._naming_the_output(
            OSError(errno.EIO, "Input/output error", str(failed)), (staging, out), out
        )
        assert exc is not None and exc.filename == str(out / "val" / "biwi_hotel.ndjson")
    elsewhere = OSError(errno.EIO, "Input/output error", str(tmp_path / "other.ndjson"))
    assert prepare._naming_the_output(elsewhere, (staging, out), out) is None
