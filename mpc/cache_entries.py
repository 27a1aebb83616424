"""What a compile-cache entry is on disk (mpc/compile_cache.py's docstring): the names of the files, the lock
of a compile, the folder it runs in, publishing a manifest, and the record of the library checked before every
load, since loading a truncated library kills the process."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Final

import casadi as ca

try:  # POSIX; without it (Windows) concurrent compiles of one entry are not serialised, only wasted
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

# The files of the cache, and the only ones cache_admin.clear removes: <key>.casadi, <key>.<tag>.so (its
# library), <key>.record, <key>.lock, and what a compile killed by SIGKILL leaves (<key>.<tag>.o,
# .tmp-<key>.<tag>.casadi and .record, crowdmpc_jit_<tag>.c: the generated source; a library no entry names).
_KEY = r"[0-9a-f]{64}"
_TAG = r"\d+_[0-9a-f]{8}"  # <pid>_<random>: the compiling process's
OWNED: Final[re.Pattern[str]] = re.compile(
    rf"{_KEY}\.(casadi|record|lock)|{_KEY}\.{_TAG}\.(so|o)|\.tmp-{_KEY}\.{_TAG}\.(casadi|record)"
    rf"|crowdmpc_jit_{_TAG}\.c"
)
ENTRY: Final[re.Pattern[str]] = re.compile(rf"{_KEY}\.casadi")
# What only a compile under way has, its process's id in the name: a SIGKILLed one's files stay behind.
_IN_PROGRESS: Final[re.Pattern[str]] = re.compile(
    rf"(?:{_KEY}\.|\.tmp-{_KEY}\.|crowdmpc_jit_)(?P<pid>\d+)_[0-9a-f]{{8}}\.(?:o|casadi|record|c)"
)
# A library, its compiling process's id in the name: a leftover too once no entry names it (a compile
# SIGKILLed while linking or before publishing left it, partial or whole, and no load ever reads it).
_LIBRARY: Final[re.Pattern[str]] = re.compile(rf"(?P<key>{_KEY})\.(?P<pid>\d+)_[0-9a-f]{{8}}\.so")
# How old such a file must be before a compile of a pid not running here counts as killed. The pid says
# nothing of a compile on another machine sharing the cache ($CROWDMPC_CACHE in a cluster's home directory,
# jobs on several nodes): its files were removed while its gcc ran, and its episodes raised. A compile uses
# each of these files within seconds of writing it; what a killed one left waits an hour more.
LEFTOVER_AGE_S: Final[float] = 3600.0


def remove_dead_leftovers(folder: Path) -> int:
    """Remove the files of compiles whose process is gone (killed: no ``finally`` ran): the generated source
    (~0.5 MB), object file, temporary manifest and record, and a library no entry names, once
    ``LEFTOVER_AGE_S`` old. Only regular files named as ours, never a symbolic link; a compile of a live
    process (this one's included) is left alone, and so is an entry's library. Returns how many."""
    removed = 0
    with os.scandir(folder) as it:
        entries = [e for e in it if OWNED.fullmatch(e.name)]
    for entry in entries:
        match = _IN_PROGRESS.fullmatch(entry.name) or _LIBRARY.fullmatch(entry.name)
        if match is None or _alive(int(match["pid"])) or not entry.is_file(follow_symlinks=False):
            continue
        if _younger_than(entry, LEFTOVER_AGE_S):  # maybe another machine's compile under way
            continue
        if match.re is _LIBRARY and _an_entrys_library(folder / f"{match['key']}.casadi", entry.name):
            continue
        with contextlib.suppress(FileNotFoundError):  # another process removed it first
            os.unlink(entry.path)
            removed += 1
    return removed


def _an_entrys_library(manifest: Path, name: str) -> bool:
    """Whether the library ``name`` may be the one of the entry ``manifest``: its record names it, or the
    entry has no record naming one (stored before records were kept: only its manifest names its library,
    and code of that time may load it). Another library of the key is no entry's: a load reads only the
    one the record names, and a record never comes to name a library of a process that is gone."""
    library = _recorded_library(manifest, _readentry_record(manifest))
    if library is None:
        return manifest.exists()
    return library.name == name


def _younger_than(entry: os.DirEntry, seconds: float) -> bool:
    """Whether ``entry`` was last written less than ``seconds`` ago (or is gone already)."""
    try:
        return time.time() - entry.stat(follow_symlinks=False).st_mtime < seconds
    except FileNotFoundError:  # another process removed it first
        return True


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (another user's too); pid 0 or one out of range is nobody's."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (OverflowError, OSError):
        return False
    return True


class NoLocks(OSError):
    """``locked``'s file system does not lock files: the caller names the folder to move (its ``filename``
    is the lock file)."""


@contextlib.contextmanager
def locked(path: Path) -> Iterator[None]:
    """Hold ``path`` (created if missing) exclusively: other processes' and threads' ``locked`` wait."""
    if fcntl is None:  # pragma: no cover
        yield
        return
    fd = _lock_descriptor(path)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError as exc:  # ENOLCK (an NFS mount without its lock daemon), EOPNOTSUPP
            raise NoLocks(exc.errno, exc.strerror, str(path)) from None
        yield
    finally:
        os.close(fd)  # releases the lock


def _lock_descriptor(path: Path, create: bool = True) -> int:
    """``path`` opened to be locked, created if missing with the permissions the umask leaves (as every file
    of the cache is: a cache a group shares under umask 002 is the group's). One another user made that this
    one may not write is opened to read, which flock takes on a local disk: a second user's compile failed
    with "Permission denied" on the first one's lock instead of waiting for it. ``create`` False: an existing
    lock, never followed through a symbolic link."""
    flags = os.O_CREAT if create else os.O_NOFOLLOW
    try:
        return os.open(path, os.O_RDWR | flags, 0o666)
    except PermissionError:
        return os.open(path, os.O_RDONLY | flags)


@contextlib.contextmanager
def unless_locked(path: Path) -> Iterator[bool]:
    """Hold ``path``, an existing lock file, if nobody holds it now (True), else hold nothing (False): what
    ``cache_admin.clear`` asks of an entry before removing its files, which a compile under way needs.
    A lock file that is gone, or another file (a symbolic link), is held by nobody; on a file system that
    does not lock files nobody can tell, and the entry counts as held, as it does when the lock is another
    user's that this one may not even read."""
    if fcntl is None:  # pragma: no cover
        yield True
        return
    try:
        fd = _lock_descriptor(path, create=False)
    except PermissionError:
        yield False
        return
    except OSError:
        yield True
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # held (BlockingIOError), or a file system that cannot say (ENOLCK): keep the files
            yield False
            return
        yield True
    finally:
        os.close(fd)  # releases the lock


def entry_key(name: str) -> str | None:
    """The key of the entry a file of ours (``OWNED``) belongs to; None for a generated source, whose name
    holds only the compiling process's tag."""
    match = re.search(_KEY, name)
    return match.group() if match else None


def publish(tmp: Path, final: Path) -> bool:
    """Move the complete file ``tmp`` to ``final`` unless ``final`` exists; whether ``tmp`` became it."""
    try:
        os.link(tmp, final)
    except FileExistsError:
        return False
    except OSError:  # a file system without hard links: replace (both are complete entries)
        os.replace(tmp, final)
        return True
    finally:
        tmp.unlink(missing_ok=True)
    return True


def _digest(path: Path) -> tuple[int, str]:
    """The size and SHA-256 of the file ``path`` (OSError when it cannot be read)."""
    h, size = hashlib.sha256(), 0
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
            size += len(block)
    return size, h.hexdigest()


def entry_record(manifest: Path, library: Path) -> str:
    """The record of an entry: what ``intact`` checks before loading it."""
    size, sha256 = _digest(library)
    return json.dumps(
        {"library": library.name, "size": size, "sha256": sha256, "manifest_sha256": _digest(manifest)[1]}
    )


def _recorded_library(manifest: Path, record: object) -> Path | None:
    """The library a record names, if it is one of this entry's (never a path out of the folder)."""
    name = record.get("library") if isinstance(record, dict) else None
    key = re.escape(manifest.name.removesuffix(".casadi"))
    if not isinstance(name, str) or not re.fullmatch(rf"{key}\.{_TAG}\.so", name):
        return None
    return manifest.parent / name


def _readentry_record(manifest: Path) -> object:
    """The record stored beside ``manifest`` (<key>.record), or None when there is none or it is no JSON."""
    try:
        return json.loads(manifest.with_suffix(".record").read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):  # RecursionError: nested past json's (recursive) parser
        return None


def intact(manifest: Path) -> bool:
    """Whether ``manifest``'s record is there and matches the manifest and, byte for byte, the library it
    names. The manifest's own hash ties the record to the manifest stored with it."""
    record = _readentry_record(manifest)
    library = _recorded_library(manifest, record)
    if library is None or not isinstance(record, dict):  # no record: an entry from before records
        return False
    try:
        stored = (record.get("size"), record.get("sha256"))
        return _digest(manifest)[1] == record.get("manifest_sha256") and _digest(library) == stored
    except OSError:  # the library is gone
        return False


def discard(manifest: Path) -> None:
    """Remove an unloadable entry: its manifest, record and the library the record names (a process that
    loaded it keeps it mapped). An entry from before records leaves its library to ``clear``."""
    library = _recorded_library(manifest, _readentry_record(manifest))
    manifest.unlink(missing_ok=True)
    manifest.with_suffix(".record").unlink(missing_ok=True)
    if library is not None:
        library.unlink(missing_ok=True)


def load_solver(manifest: Path) -> ca.Function | None:
    """The solver of an entry, or None when it cannot be loaded (missing, no record, its library gone or not
    the one stored: checked first, since loading a truncated library is a bus error)."""
    if not manifest.is_file() or not intact(manifest):
        return None
    try:
        return ca.Function.load(str(manifest))
    except RuntimeError:
        return None


# Held while a compile has moved the process into the cache folder (inside): two threads' compiles must not
# interleave their moves, or the process would be left in a cache folder.
_CWD_LOCK = threading.Lock()
# How the directory to come back to is held: O_PATH (Linux) needs no read permission on it.
_HERE: Final[int] = getattr(os, "O_PATH", os.O_RDONLY) | getattr(os, "O_DIRECTORY", 0)


@contextlib.contextmanager
def inside(folder: Path) -> Iterator[None]:
    """Run with ``folder`` as the process's working directory, then return to the one before (held by a
    descriptor: found again even if renamed or removed meanwhile).

    Why: CasADi writes a solver's generated source to <jit_name>.c in the working directory (jit_name may not
    hold a directory, and CasADi 3.8 has no option for one), where it failed when that is not writable and a
    killed compile left it. The working directory is the whole process's: for the seconds of a compile, a
    relative path opened by another thread would resolve in ``folder``. Nothing of this project runs beside
    a compile and opens one: DMPC's other solver threads only solve (builds take solvers._BUILD_LOCK), and
    episodes, recorders and an inline sweep run in the thread that builds the solvers, before or after the
    build. A program embedding this module whose own threads open relative paths should keep them apart
    from a cold compile (or warm the cache first).
    """
    with _CWD_LOCK:
        try:
            back = os.open(".", _HERE)
        except OSError as exc:
            # a RuntimeError, as CasADi's own failures: compile_cache.nlpsol makes it a CompileCacheError
            raise RuntimeError(f"cannot hold the working directory to come back to it ({exc})") from exc
        try:
            os.chdir(folder)
            yield
        finally:
            os.fchdir(back)
            os.close(back)
