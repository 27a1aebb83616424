"""What ``crowdmpc cache info|clear`` does to the compile cache (mpc/compile_cache.py): count its entries and
size, and remove the files of ours, never an entry a compile under way holds."""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path

import casadi as ca

from mpc.cache_entries import ENTRY, OWNED, entry_key, unless_locked
from mpc.cache_location import readable_dir
from mpc.compile_cache import COMPILER, compiler
from mpc.errors import CompileCacheError


@dataclass(frozen=True)
class CacheInfo:
    """What ``crowdmpc cache info`` prints."""

    directory: Path
    exists: bool
    entries: int  # compiled solvers
    files: int  # files of ours, leftovers included
    size_bytes: int
    casadi_version: str
    compiler: str  # Compiler.describe(), or why there is none


def _owned_files(folder: Path) -> list[os.DirEntry]:
    """Regular files of ours directly in ``folder``: names we write, never a symlink, never a folder."""
    if not folder.is_dir():
        return []
    with os.scandir(folder) as it:
        return [e for e in it if OWNED.fullmatch(e.name) and e.is_file(follow_symlinks=False)]


def info(directory: str | Path | None = None) -> CacheInfo:
    """The cache's location, entries and size, and what compiles into it."""
    folder = readable_dir(directory)
    files = _owned_files(folder)
    cc = compiler()
    return CacheInfo(
        directory=folder,
        exists=folder.is_dir(),
        entries=sum(1 for e in files if ENTRY.fullmatch(e.name)),
        files=len(files),
        size_bytes=sum(e.stat(follow_symlinks=False).st_size for e in files),
        casadi_version=ca.__version__,
        compiler=cc.describe() if cc is not None else f"none ({COMPILER} not on the PATH)",
    )


def clear(directory: str | Path | None = None) -> tuple[int, int, int]:
    """Remove the files of ours in the cache directory (not the directory, nor anything else in it).

    Returns (files removed, bytes freed, entries left): an entry another process compiles now (it holds the
    entry's lock) keeps its files, and the generated sources stay with it, or that compile fails (gcc or the
    linker finds its file gone, or the entry it stored does not load). A directory that is a symlink is
    refused: its files live elsewhere. A process that loaded an entry keeps using it (an unlinked library
    stays mapped); the next build compiles.
    """
    folder = readable_dir(directory)
    if folder.is_symlink():
        raise CompileCacheError(f"{folder} is a symlink; not clearing files outside the cache")
    by_key: dict[str | None, list[os.DirEntry]] = {}
    for entry in _owned_files(folder):
        by_key.setdefault(entry_key(entry.name), []).append(entry)
    sources = by_key.pop(None, [])  # no key in their name: whose they are is unknown
    removed = freed = 0
    busy = 0
    for key, files in sorted(by_key.items()):
        # held while its files go, the lock file last: a compile starting now waits, then compiles anew
        with unless_locked(folder / f"{key}.lock") as free:
            if not free:
                busy += 1
                continue
            files.sort(key=lambda e: e.name.endswith(".lock"))
            removed, freed = _remove(files, removed, freed)
    if not busy:
        removed, freed = _remove(sources, removed, freed)
    return removed, freed, busy


def _remove(files: list[os.DirEntry], removed: int, freed: int) -> tuple[int, int]:
    """Unlink ``files``, adding to the count ``removed`` and the bytes ``freed`` of those unlinked."""
    for entry in files:
        with contextlib.suppress(FileNotFoundError):  # another process removed it first
            size = entry.stat(follow_symlinks=False).st_size
            try:
                os.unlink(entry.path)
            except FileNotFoundError:
                raise
            except OSError as exc:  # a folder the user may not write: say which file, and what went already
                raise CompileCacheError(
                    f"cannot remove {entry.path} ({exc.strerror or exc}); {removed} file"
                    + ("" if removed == 1 else "s")
                    + " removed before it"
                ) from None
            removed += 1
            freed += size
    return removed, freed
