"""User-named figures and animations replace an earlier file of their name whole or not at all: matplotlib
wrote them in place, so a save that failed part way (a full disk, an error while drawing, a kill) had already
emptied the earlier figure."""

from __future__ import annotations

import errno
import fcntl
import os
import stat
import time
from pathlib import Path

import pytest
from matplotlib.animation import PillowWriter
from matplotlib.figure import Figure

from pipelines.cli import main
from pipelines.whole_files import save_figure
from predictors.locking import unless_held
from tests.pipelines.test_compare import BASE, NEW, _record, _sweep

EARLIER = b"the earlier figure"


def _half_then_full_disk(target: object) -> None:
    """What a save cut short leaves: some bytes of the new file, then the error."""
    with open(str(target), "wb") as f:
        f.write(b"\x89PNG half")
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.fixture
def failing_saves(monkeypatch):
    def savefig(self, fname, *args, **kwargs):
        if isinstance(fname, (str, os.PathLike)):  # an animation's frames go to a buffer: drawn as ever
            _half_then_full_disk(fname)
        return original(self, fname, *args, **kwargs)

    original = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", savefig)
    monkeypatch.setattr(PillowWriter, "finish", lambda self: _half_then_full_disk(self.outfile))


def _recording(folder: Path) -> Path:
    from tests.pipelines.mcap_episode import record_episode

    return record_episode(folder, seed=1, steps=3).path


COMMANDS = [
    "simulate",
    "compare",
    "zoo calibrations",
    "review --plot",
    "review --animate",
    "review --compare",
]


@pytest.mark.parametrize("command", COMMANDS)
def test_a_save_that_fails_part_way_leaves_the_earlier_figure(tmp_path, capsys, failing_saves, command):
    out = tmp_path / "out"
    out.mkdir()
    target = out / ("a.gif" if command == "review --animate" else "a.png")
    target.write_bytes(EARLIER)
    if command == "simulate":
        argv = ["simulate", "--controller", "straight", "--humans", "1", "--no-progress"]
        argv += ["--plot", str(target)]
    elif command == "compare":
        a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
        b = _sweep(tmp_path / "b", [_record(i, *o) for i, o in enumerate(NEW)])
        argv = ["compare", str(a), str(b), "--plot", str(target)]
    elif command == "zoo calibrations":
        argv = ["zoo", "calibrations", "--predictor", "constant_velocity", "--plot", str(target)]
    else:
        recording = _recording(tmp_path / "run")
        option = command.split()[1]
        argv = ["review", str(recording), "--animate" if option == "--animate" else "--plot", str(target)]
        if option == "--compare":
            argv += ["--compare", str(recording)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "No space left on device" in err and err.count("\n") == 1
    assert target.read_bytes() == EARLIER
    assert [p.name for p in out.iterdir()] == [target.name]  # no temporary left beside it


def test_a_saved_figure_replaces_the_earlier_one_keeping_its_mode(tmp_path):
    """The temporary keeps the suffix (matplotlib's format is the name's: a PDF here, not a PNG) and the new
    file the earlier one's permissions, not mkstemp's 0600."""
    target = tmp_path / "f.pdf"
    target.write_bytes(EARLIER)
    target.chmod(0o640)
    figure = Figure()
    figure.add_subplot().plot([0, 1], [1, 0])
    save_figure(target, figure.savefig)
    assert target.read_bytes().startswith(b"%PDF")
    assert stat.S_IMODE(target.stat().st_mode) == 0o640
    assert [p.name for p in tmp_path.iterdir()] == ["f.pdf"]


def test_the_temporaries_of_killed_saves_are_removed_by_the_next_save(tmp_path):
    """A figure saved by a run killed before its rename (kill -9, SIGTERM: no finally runs) left its
    ".crowdmpc-figure-XXXXXXXX.png" in the folder for good, one more per kill (an animation's as large as
    the animation). The next save into that folder removes them, whichever figure they were for; never a
    temporary a live save holds locked, nor one just made (its save may not have locked it yet), nor a
    folder or a file of another name."""
    old = time.time() - 3600
    killed = [tmp_path / ".crowdmpc-figure-k1ll3d_0.png", tmp_path / ".crowdmpc-figure-k1ll3d_1.gif"]
    live = tmp_path / ".crowdmpc-figure-l1ve0000.png"
    kept = [live, tmp_path / ".crowdmpc-figure-fresh000.png", tmp_path / ".crowdmpc-figure-short.png"]
    folder = tmp_path / ".crowdmpc-figure-folder00.png"
    folder.mkdir()
    for path in [*killed, *kept]:
        path.write_bytes(b"half")
        if path.name != ".crowdmpc-figure-fresh000.png":
            os.utime(path, (old, old))
    os.utime(folder, (old, old))
    figure = Figure()
    figure.add_subplot().plot([0, 1], [1, 0])
    locked_while_saved = []

    def save(name: str) -> None:
        with unless_held(Path(name), gone=True) as free:  # as the next save's look sees this one's
            locked_while_saved.append(not free)
        figure.savefig(name)

    with open(live, "rb+") as held:  # another process's save, still writing
        fcntl.flock(held, fcntl.LOCK_EX)
        save_figure(tmp_path / "f.png", save)
    assert locked_while_saved == [True]
    left = {p.name for p in tmp_path.iterdir()}
    assert left == {"f.png", folder.name, *(p.name for p in kept)}
