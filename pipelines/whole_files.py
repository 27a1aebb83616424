"""Outputs written whole or not at all: made under a temporary name beside the output, then renamed over it,
so that a write that fails part way leaves an earlier file of that name as it was. A leaf: the commands and
the pictures of ``pipelines.logs`` import it, it imports nothing of theirs."""

from __future__ import annotations

import contextlib
import os
import re
import stat
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Final

# The temporary a figure is saved under: its length does not grow with the output's name (a 240-byte --plot
# is written), so check_writable needs no room for it (room=0).
FIGURE_TEMPORARY_PREFIX: Final[str] = ".crowdmpc-figure-"
# Its whole name: mkstemp's eight random characters, then the suffix of whichever figure it was made for.
FIGURE_TEMPORARY: Final[re.Pattern[str]] = re.compile(
    rf"{re.escape(FIGURE_TEMPORARY_PREFIX)}[a-z0-9_]{{8}}(?:\.[^.]*)?"
)
# Older than this and unlocked, a temporary made beside an output is a killed writer's: a live one locks its
# file within microseconds of creating it.
TEMPORARY_MIN_AGE_S: Final[float] = 60.0


def new_file_mode(path: Path) -> int:
    """The mode of a new file that replaces ``path``: the mode of the file it replaces, else the umask's
    (``mkstemp`` makes its files 0600, which a figure or a report shared with others must not keep)."""
    if path.is_file():
        return stat.S_IMODE(path.stat().st_mode)
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def save_figure(path: Path, save: Callable[[str], object]) -> None:
    """``save(name)`` writes a user-named figure or animation (``Figure.savefig``, ``Animation.save``) under a
    temporary name in ``path``'s folder, which then replaces ``path`` in one rename: a save that raises part
    way (a full disk, a drawing error, a Ctrl-C) leaves an earlier file of that name as it was, and no
    temporary. The temporary keeps ``path``'s suffix, from which matplotlib, Pillow and ffmpeg take the
    format. Saved in place: an existing ``path`` that is not a regular file (a device, a pipe: the rename
    would replace the node itself), and a file whose folder takes no new entries (check_writable let it
    through: the file itself is writable). The temporary is locked while it is saved, and those that killed
    saves left in the folder (``FIGURE_TEMPORARY``) are removed."""
    path = Path(path)
    if path.exists() and not path.is_file():
        save(str(path))
        return
    remove_killed_temporaries(path.parent, FIGURE_TEMPORARY)
    try:
        fd, name = tempfile.mkstemp(prefix=FIGURE_TEMPORARY_PREFIX, suffix=path.suffix, dir=path.parent)
    except PermissionError:
        if not path.is_file():
            raise
        save(str(path))
        return
    fill_and_rename(fd, name, path, save)


def fill_and_rename(fd: int, name: str, path: Path, write: Callable[[str], object]) -> None:
    """``write(name)`` fills the temporary ``name`` (open at ``fd``, locked meanwhile, given ``path``'s
    mode), which then replaces ``path`` in one durable rename (``replace_durably``: synced before it, the
    folder after); the temporary is removed and ``fd`` closed whatever happens (``save_figure``'s and
    ``replace_file``'s)."""
    from predictors.durable import replace_durably  # not at import: the predictors package loads casadi

    try:
        lock_temporary(fd)
        os.chmod(name, new_file_mode(path))
        write(name)
        replace_durably(name, path)
    finally:
        if os.path.lexists(name):
            os.unlink(name)
        os.close(fd)


def lock_temporary(fd: int) -> None:
    """Lock the temporary open at ``fd`` until it is closed, after its rename: what tells a live writer's
    temporary from one a kill left (kill -9, or a SIGTERM, which runs no finally)."""
    import fcntl

    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
    except OSError:  # a file system that cannot lock (ENOLCK): its temporaries are never removed
        pass


def remove_killed_temporaries(folder: Path, temporary: re.Pattern[str]) -> None:
    """Remove the temporaries in ``folder`` whose names ``temporary`` matches that writers killed before their
    rename left there: each is as large as its output (an export's CasADi file, an animation), and every
    killed run added one for good. Only regular files nobody holds locked (``lock_temporary``), written over
    ``TEMPORARY_MIN_AGE_S`` ago; a file system that cannot lock keeps them all (``unless_held``)."""
    from predictors.locking import unless_held

    try:
        entries = [entry for entry in os.scandir(folder) if temporary.fullmatch(entry.name)]
    except OSError:  # the folder unreadable or missing: the write that follows says why
        return
    for entry in entries:
        try:
            info = entry.stat(follow_symlinks=False)
        except OSError:
            continue
        if not stat.S_ISREG(info.st_mode) or time.time() - info.st_mtime < TEMPORARY_MIN_AGE_S:
            continue
        with unless_held(Path(entry.path), gone=False) as free, contextlib.suppress(OSError):
            if free:
                Path(entry.path).unlink(missing_ok=True)
