"""Files replaced durably: written under a temporary name, synced, renamed over the output, and the rename
synced with the folder that holds it. A rename alone leaves a file whole after a kill, but not after a power
loss: the file system may put the rename on disk before the data it names (XFS, ext4 mounted
noauto_da_alloc: an empty file under the output's name), or lose the rename itself (the output reverts, or
never appears, though the command said it was written). Every rename of an output in ``predictors`` and
``pipelines`` goes through ``replace_durably``; it lives here, below ``pipelines``, so that both may call
it."""

from __future__ import annotations

import errno
import os
from pathlib import Path

StrPath = str | os.PathLike[str]


# fsync's answer on a file system that does not sync files (some FUSE and network ones): the data is written
# as before the syncs were made, only its durability is left unsure, as a folder's is (sync_folder)
_CANNOT_SYNC = frozenset({errno.EINVAL, errno.EOPNOTSUPP})


class SyncFailed(OSError):
    """A file's data the storage did not put on disk when synced (EIO; a full disk or a quota that NFS
    reports only then): the write failed though every write() had returned. It names the file, which the
    fsync's error does not, so that the CLI's line says which output was not written."""


def sync_file(path: StrPath) -> None:
    """``path``'s data on disk (an fsync through a descriptor of its own: the writer's may be closed)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError as exc:
        if exc.errno not in _CANNOT_SYNC:
            raise SyncFailed(exc.errno, exc.strerror, os.fspath(path)) from None
    finally:
        os.close(fd)


def sync_folder(folder: StrPath) -> None:
    """The entries of ``folder`` (a rename into it, a file made in it) on disk. A file system that cannot
    sync a folder (EINVAL on some network ones), or a folder that cannot be opened, is let be: the files
    themselves are written, only their names' durability is left unsure."""
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def replace_durably(source: StrPath, target: StrPath, *, sync_target_folder: bool = True) -> None:
    """``source`` (a written temporary) renamed over ``target``, durably: ``source`` synced before the rename,
    ``target``'s folder after it. ``sync_target_folder=False`` leaves that last sync to a caller that renames
    several files into one folder (a report, a training run's pair) and syncs it once (``sync_folder``)."""
    sync_file(source)
    os.replace(source, target)
    if sync_target_folder:
        sync_folder(Path(target).parent)


def write_text_durably(path: Path, text: str) -> None:
    """Make ``text`` the content of ``path`` (a zoo's manifest or calibrations) in one durable rename of a
    temporary (``.NAME.PID.tmp``, the pid keeping two writers apart): an unsynced one could leave, after a
    power loss, an empty manifest (every model of the zoo lost) or one naming files an add had put in place
    but not yet made durable."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with tmp.open("w", encoding="utf-8") as handle:
            handle.write(text)
        replace_durably(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)  # a full disk (or a Ctrl-C) leaves no half-written temporary behind
