"""Where the compile cache lives (mpc/compile_cache.py): ``$CROWDMPC_CACHE/compiled``, else the XDG or home
cache folder, and whether that directory can be read, written and compiled into (CasADi's shell compiler
passes it to gcc unquoted). A directory that cannot is a ``CacheLocationError``: one line naming
$CROWDMPC_CACHE and what is wrong."""

from __future__ import annotations

import errno
import os
import pwd
import re
import shutil
import sys
from pathlib import Path
from typing import Final

from mpc.errors import CacheLocationError

# The variable and default of predictors.data.locate.cache_root, repeated here: importing predictors would
# cost mpc a second of imports (trajnetplusplustools) and a dependency it does not otherwise have.
CACHE_ENV: Final[str] = "CROWDMPC_CACHE"
SUBDIR: Final[str] = "compiled"
# What the shell splits a word on or reads specially: a path holding one is refused (``_shell_unsafe``). Any
# other character, a non-ASCII letter among them (/home/josé), reaches gcc as it is; a resolved path starts
# with "/", so a "~" in it is never expanded.
SHELL_SPECIAL: Final[re.Pattern[str]] = re.compile(r"[\s'\"\\$`;&|<>()*?\[\]#!{}]")
SHELL_SAFE: Final[str] = (
    "a writable directory whose path is UTF-8 and has no space and none of '\"\\$`;&|<>()*?[]#!{}"
)


def cache_dir() -> Path:
    """``$CROWDMPC_CACHE/compiled``, else ``$XDG_CACHE_HOME/crowdmpc/compiled`` (an absolute one only, as
    the XDG spec says), else ``~/.cache/crowdmpc/compiled`` (not created here); the prepared data's root is
    the same folder (``predictors.data.locate.cache_root``)."""
    root = os.environ.get(CACHE_ENV)
    if root and (root == "~" or root.startswith("~/")):  # lstrip: home / "/x" of "~//x" is /x
        return _home(f"${CACHE_ENV} {root}", " to an absolute path") / root[2:].lstrip("/") / SUBDIR
    if root:
        try:
            return Path(root).expanduser() / SUBDIR  # ~user/...: the password database, never $HOME
        except RuntimeError:  # ~user of no user: Python's error names no variable
            raise CacheLocationError(f"${CACHE_ENV} {root}: no such user, so no home") from None
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg and Path(xdg).is_absolute() else _home("the compile cache") / ".cache"
    return base / "crowdmpc" / SUBDIR


def _home(what: str, wanted: str = "") -> Path:
    """An absolute ``$HOME``, else the password database's home (``Path.home()`` took ``HOME=`` for "/"):
    predictors.home.home_dir repeated, as CACHE_ENV is, for mpc and predictors import nothing of each other
    and share only crowdsim.world, which holds the world's facts."""
    home = os.environ.get("HOME")
    if home and Path(home).is_absolute():
        return Path(home)
    try:
        entry = pwd.getpwuid(os.getuid()).pw_dir
    except KeyError:
        entry = ""
    if not Path(entry).is_absolute():  # no password entry, or one without a home
        raise CacheLocationError(
            f"cannot find the home directory for {what} (no absolute $HOME, and none in the password "
            f"database); set ${CACHE_ENV}{wanted}"
        )
    return Path(entry)


def _nearest_existing(path: Path) -> Path:
    return next(p for p in (path, *path.parents) if os.path.lexists(p))


def free_bytes(directory: str | Path | None = None) -> int:
    """Free space on the file system the cache is (or would be made) on, for this user."""
    return shutil.disk_usage(_nearest_existing(Path(directory) if directory else cache_dir())).free


def _file_in_the_way(path: Path) -> Path | None:
    """The nearest existing one of ``path`` and its parents when it is no directory (a file, a dangling or
    looping symbolic link): then ``path`` can be no directory."""
    existing = _nearest_existing(path)
    return None if existing.is_dir() else existing


def _unwritable(path: Path) -> str | None:
    """Why the directory ``path`` cannot be written in, creating it (and its parents) when it can."""
    existing = _nearest_existing(path)
    if not existing.is_dir():
        return f"{existing} is not a directory"
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):  # a read-only or foreign place
            return f"{existing} is not writable ({exc.strerror})"
        return f"{path} cannot be created ({exc.strerror or exc})"
    if not os.access(path, os.W_OK | os.X_OK):
        return f"{path} is not writable"
    return None


def _shell_unsafe(path: Path) -> str | None:
    """Why CasADi cannot compile into the directory ``path``, or None: its "shell" compiler pastes the
    directory into a command line unquoted, so a space (or any character the shell splits on or interprets)
    makes gcc write its output at another path, outside the cache, and the build fail."""
    try:
        resolved = str(path.resolve())
    except (OSError, RuntimeError):  # a symbolic link loop: _unwritable names it
        return None
    if not _utf8(resolved):  # undecodable bytes: CasADi receives "" for the path
        if _utf8_bytes(resolved):  # UTF-8 on disk, but the locale's encoding (ASCII) could not read it
            encoding = sys.getfilesystemencoding()
            return (
                f"its path {resolved!r} is not text in this locale's encoding ({encoding}), which CasADi "
                "cannot pass to gcc: run under a UTF-8 locale (LANG=C.UTF-8) or name an ASCII path"
            )
        return f"its path {resolved!r} is not UTF-8, which CasADi cannot pass to gcc"
    if SHELL_SPECIAL.search(resolved) is None:
        return None
    return f"its path {resolved!r} holds a space or shell character, which CasADi passes to gcc unquoted"


def _utf8_bytes(text: str) -> bool:
    """Whether the bytes behind ``text`` (a path as Python decoded it) are valid UTF-8."""
    try:
        os.fsencode(text).decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


def _utf8(text: str) -> bool:
    """Whether ``text`` (a path as Python decodes it, undecodable bytes as surrogates) is valid UTF-8."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def location_error(
    folder: Path, directory: str | Path | None, problem: str, wanted: str = "a writable directory"
) -> CacheLocationError:
    """The one-line error about a cache directory that cannot be used (naming $CROWDMPC_CACHE if set)."""
    if directory is not None:
        return CacheLocationError(f"the compile cache {folder}: {problem}")
    root = os.environ.get(CACHE_ENV)
    named = f"${CACHE_ENV}={root}" if root else f"the compile cache {folder} (default; ${CACHE_ENV} unset)"
    return CacheLocationError(f"{named}: {problem}; set ${CACHE_ENV} to {wanted}")


def readable_dir(directory: str | Path | None) -> Path:
    """The cache directory, not created: ``CacheLocationError`` when a file stands where it must be (it is
    then not "not created yet", nor empty: it cannot be)."""
    path = Path(directory) if directory is not None else cache_dir()
    blocker = _file_in_the_way(path)
    if blocker is not None:
        raise location_error(path, directory, f"{blocker} is not a directory")
    return path


def writable_dir(directory: str | Path | None = None) -> Path:
    """The cache directory (``directory``, else ``cache_dir()``), created, about to be written in;
    ``CacheLocationError`` naming $CROWDMPC_CACHE and what is wrong when it cannot be (a caller may check
    this before starting workers)."""
    path = Path(directory) if directory is not None else cache_dir()
    unsafe = _shell_unsafe(path)  # checked first: such a directory is refused, so it is not created either
    if unsafe is not None:
        raise location_error(path, directory, unsafe, SHELL_SAFE)
    problem = _unwritable(path)
    if problem is not None:
        raise location_error(path, directory, problem)
    return path
