"""An exclusive lock on a file for a ``with`` block: how preparations of one folder wait for each other."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from pathlib import Path

from predictors.errors import PredictorError

try:  # POSIX; without it (Windows) preparations are not serialised, and the last to finish wins
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]


@contextlib.contextmanager
def locked(path: Path, waiting: Callable[[], None] | None = None) -> Iterator[None]:
    """Hold ``path`` (created if missing, never through a symbolic link) exclusively: other processes'
    ``locked`` on it wait, calling ``waiting`` first. The file stays: removing it would let a waiter and a
    newcomer lock two different files."""
    if fcntl is None:  # pragma: no cover
        yield
        return
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    except OSError as exc:
        raise PredictorError(
            f"the lock file {path} cannot be opened ({exc.strerror or exc}); remove it if it is a link"
        ) from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if waiting is not None:
                waiting()
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock
