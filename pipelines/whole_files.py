"""Outputs written whole or not at all: made under a temporary name beside the output, then renamed over it,
so that a write that fails part way leaves an earlier file of that name as it was. A leaf: the commands and
the pictures of ``pipelines.logs`` import it, it imports nothing of theirs."""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Final

# The temporary a figure is saved under: its length does not grow with the output's name (a 240-byte --plot
# is written), so check_writable needs no room for it (room=0).
FIGURE_TEMPORARY_PREFIX: Final[str] = ".crowdmpc-figure-"


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
    through: the file itself is writable)."""
    path = Path(path)
    if path.exists() and not path.is_file():
        save(str(path))
        return
    try:
        fd, name = tempfile.mkstemp(prefix=FIGURE_TEMPORARY_PREFIX, suffix=path.suffix, dir=path.parent)
    except PermissionError:
        if not path.is_file():
            raise
        save(str(path))
        return
    os.close(fd)
    try:
        os.chmod(name, new_file_mode(path))
        save(name)
        os.replace(name, path)
    finally:
        if os.path.lexists(name):
            os.unlink(name)
