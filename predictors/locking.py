"""An exclusive lock on a file for a ``with`` block: how the writers of a zoo's manifest, and preparations
of one data folder, wait for each other; and whether the process a leftover file names still runs.

A lock file rather than the folder itself: on NFS (home directories on clusters) flock is emulated with fcntl
locks, which need a file opened for writing. The file stays once released, unless a failed run removes the
one it made: a lock taken is held only while its path still names it, else taken anew, so that a waiter and a
newcomer never lock two different files."""

from __future__ import annotations

import fcntl
import os
import re
import stat
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from itertools import takewhile
from pathlib import Path
from typing import Final

from predictors.errors import PredictorError

_RETAKES = 8  # a removed lock is retaken at once: more than a few in a row is a file system, not a race
# The hidden locks crowdmpc's writers leave once released: data synth's and data prepare's beside what they
# write (.NAME.synth.lock, .NAME.prepare.lock), train's and sweep's in their folder.
LEFT_LOCK: Final = re.compile(r"\.(?:.+\.(?:synth|prepare)|train|sweep)\.lock")


@contextmanager
def locked(path: Path, purpose: str, waiting: Callable[[], None] | None = None) -> Iterator[None]:
    """Hold ``path`` (created if missing) exclusively: other processes' ``locked`` on it wait, after calling
    ``waiting``. PredictorError "``path``: cannot ``purpose`` (why)" when it cannot be a lock: a symbolic
    link planted there must not make us create a file elsewhere (O_NOFOLLOW), nor a FIFO block the open for
    ever (O_NONBLOCK, then anything but a regular file refused)."""
    for retake in range(_RETAKES + 1):
        fd = _open_lock(path, purpose)
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise PredictorError(f"{path}: cannot {purpose} (not a regular file); remove it")
            try:
                _lock(fd, waiting)
            except OSError as exc:  # ENOLCK (an NFS mount without its lock daemon), EOPNOTSUPP: not ours
                raise PredictorError(
                    f"{path}: cannot {purpose} ({exc.strerror}: its file system does not lock files; an NFS "
                    "mount without its lock daemon?)"
                ) from None
            # A failed run removes a lock it made (remove_made_folders): one opened before that and locked
            # after it is a file no newcomer opens, so both would run; such a lock is taken again, anew.
            # A file system whose stat and fstat disagree on a file's identity (some overlay mounts' inode
            # numbers) would retake for ever: past a few retakes the lock is held as it was before removal.
            if _names(path, fd) or retake == _RETAKES:
                yield
                return
        finally:
            os.close(fd)  # releases the lock


def _open_lock(path: Path, purpose: str) -> int:
    try:
        # 0o666: the umask decides, as for every file open() makes (a group's shared folder under umask 002)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NOFOLLOW | os.O_NONBLOCK, 0o666)
    except OSError as exc:
        if os.path.islink(path):
            raise PredictorError(f"{path}: cannot {purpose} (it is a symbolic link)") from None
        if _planted(path):  # the open's own error said "No such device or address" for a FIFO
            raise PredictorError(f"{path}: cannot {purpose} (not a regular file); remove it") from None
        raise PredictorError(f"{path}: cannot {purpose} ({exc.strerror or exc})") from None
    return fd


def _names(path: Path, fd: int) -> bool:
    """Whether ``path`` is still the file open as ``fd``."""
    try:
        here = os.lstat(path)
    except OSError:
        return False
    there = os.fstat(fd)
    return (here.st_dev, here.st_ino) == (there.st_dev, there.st_ino)


def _lock(fd: int, waiting: Callable[[], None] | None) -> None:
    """Lock ``fd`` exclusively, calling ``waiting`` first when another process holds it."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        if waiting is not None:
            waiting()
        fcntl.flock(fd, fcntl.LOCK_EX)


@contextmanager
def unless_held(path: Path, gone: bool) -> Iterator[bool]:
    """Hold ``path``, a lock file its writer holds while it runs, if nobody holds it now (True), else hold
    nothing (False); ``gone``: the answer for a file that is not there, or is no regular file. Unlike a pid,
    a lock tells a writer on another machine sharing the folder (a cluster's home directory) from a
    finished one. On a file system that does not lock files (an NFS mount without its lock daemon) nobody can
    tell, and the file counts as held: what it guards is kept, never removed under a writer."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        yield gone
        return
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            yield gone
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # held (BlockingIOError), or a file system that cannot say (ENOLCK): keep the files
            yield False
            return
        yield True
    finally:
        os.close(fd)  # releases the lock


def released_locks(folder: Path) -> set[str]:
    """The names of ``folder``'s crowdmpc locks (``LEFT_LOCK``) that no process holds now: what a finished
    command leaves by design, and `rm DIR/*` leaves behind (the glob skips hidden names), so a folder that
    holds nothing else is as good as empty for a new output. A held lock, a link or a file system that cannot
    tell is not among them: the folder then stays another command's."""
    names = set()
    for entry in folder.iterdir():
        if LEFT_LOCK.fullmatch(entry.name):
            with unless_held(entry, gone=False) as free:
                if free:
                    names.add(entry.name)
    return names


def _planted(path: Path) -> bool:
    """Whether something other than a regular file is at ``path`` (a FIFO with no reader, a directory)."""
    try:
        return not stat.S_ISREG(os.lstat(path).st_mode)
    except OSError:
        return False


def remove_made_folders(lock: Path, made: list[Path], lock_made: bool = False) -> None:
    """For a run that failed holding ``lock``, which made the folders ``made`` (innermost first, the lock's
    own among them): remove them where the lock is all they hold, the lock first while still held (a run
    that opened it meanwhile and tries it now is refused), so that a failed run leaves nothing it made.
    ``lock_made``: the run made the lock itself, which goes even from a folder it found (a sweep refused a
    folder a failed `data synth` had left its lock in as one holding files)."""
    if made and [p.name for p in lock.parent.iterdir()] == [lock.name]:
        lock.unlink()
        for folder in made:
            try:
                folder.rmdir()
            except OSError:  # something else was put there meanwhile: not ours to remove
                break
    elif lock_made:
        lock.unlink(missing_ok=True)


@contextmanager
def locked_undone_on_failure(
    lock: Path, purpose: str, waiting: Callable[[], None] | None = None
) -> Iterator[None]:
    """``locked`` on ``lock``, its folder made as needed; a run that fails inside leaves neither the lock
    where it made it nor a folder it made for it (``remove_made_folders``): a failed run's lock had the
    folder it found refused by a sweep --out as one holding files. Judged on the folder as resolved (in
    a/x/../../b with a/x missing, an existing b does not exist as named)."""
    folder = lock.parent.resolve()
    made = list(takewhile(lambda parent: not parent.exists(), (folder, *folder.parents)))
    lock_made = not os.path.lexists(lock)
    folder.mkdir(parents=True, exist_ok=True)
    with locked(lock, purpose, waiting):
        try:
            yield
        except BaseException:
            remove_made_folders(lock, made, lock_made)
            raise


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs: what a staging folder, a journal or a scratch folder named by its
    writer's pid is judged by (kept while its writer runs, removed once it is gone). Another user's process
    counts as running; a zombie, ended and not yet reaped, does not."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process: alive
        return True
    return not _zombie(pid)


def _zombie(pid: int) -> bool:
    """Whether ``pid`` ended and waits for its parent to reap it: ``kill(pid, 0)`` still finds it, yet it
    writes nothing more. A preparer killed holding the cache entry's lock is one at the very moment the
    waiter takes that lock, and its staging was then kept for good. False where there is no /proc."""
    try:
        with open(f"/proc/{pid}/stat", encoding="utf-8") as f:
            stat = f.read()
    except OSError:
        return False
    return stat[stat.rfind(")") + 2 :].startswith("Z")  # the state follows the command name in brackets
