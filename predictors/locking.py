"""An exclusive lock on a file for a ``with`` block: how the writers of a zoo's manifest, and preparations
of one data folder, wait for each other.

A lock file rather than the folder itself: on NFS (home directories on clusters) flock is emulated with fcntl
locks, which need a file opened for writing. The file stays once released: removing it would let a waiter
and a newcomer lock two different files."""

from __future__ import annotations

import fcntl
import os
import stat
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from predictors.errors import PredictorError


@contextmanager
def locked(path: Path, purpose: str, waiting: Callable[[], None] | None = None) -> Iterator[None]:
    """Hold ``path`` (created if missing) exclusively: other processes' ``locked`` on it wait, after calling
    ``waiting``. PredictorError "``path``: cannot ``purpose`` (why)" when it cannot be a lock: a symbolic
    link planted there must not make us create a file elsewhere (O_NOFOLLOW), nor a FIFO block the open for
    ever (O_NONBLOCK, then anything but a regular file refused)."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    except OSError as exc:
        what = "it is a symbolic link" if os.path.islink(path) else (exc.strerror or str(exc))
        raise PredictorError(f"{path}: cannot {purpose} ({what})") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise PredictorError(f"{path}: cannot {purpose} (not a regular file); remove it")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if waiting is not None:
                waiting()
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock
