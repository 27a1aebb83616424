"""A sweep directory as a whole: the check that a folder may hold a sweep (no other files, none of the sweep's
own a link) before anything of it is read or written, and the lock that keeps it to one sweep at a time. The
names of its files and its episode log are pipelines.experiments.log."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Final

from pipelines.errors import PipelineError
from pipelines.experiments.log import (
    CUT_SUFFIX,
    EPISODES_FILE,
    ERRORS_FILE,
    LOCK_FILE,
    MCAP_DIR,
    PART_SUFFIX,
    SWEEP_FILE,
)

# What a sweep writes at the top of its directory besides its files' names: the report (tables, CSVs, plots)
# and the temporary files replaced into place
OWN_SUFFIXES: Final[tuple[str, ...]] = (".csv", ".md", ".png", PART_SUFFIX)


def check_sweep_directory(out: Path, option: str = "--out") -> None:
    """Before anything of ``out`` is read or written: refuse a folder of other files (a sweep would overwrite
    them with its tables), and any of the sweep's own files that is a symbolic link (the sweep would read,
    cut and append to a file elsewhere). A missing or empty folder, and a sweep directory, are fine."""
    if not out.is_dir():
        return
    entries = {entry.name: entry for entry in out.iterdir()}
    # the lock and the temporary sweep.json of a sweep stopped while it wrote its first record are its own
    leftovers = {LOCK_FILE, *(name + PART_SUFFIX for name in (SWEEP_FILE, EPISODES_FILE, ERRORS_FILE))}
    if entries.keys() - leftovers and not entries.keys() & {SWEEP_FILE, EPISODES_FILE}:
        from predictors.locking import released_locks

        # a finished `data synth`'s lock stays in its folder by design, and `rm DIR/*` skips it
        if entries.keys() - leftovers - released_locks(out):
            raise PipelineError(
                f"{option} {out} holds files but no sweep ({SWEEP_FILE}, {EPISODES_FILE}); a sweep would "
                "overwrite them: choose an empty or new folder"
            )
    own = (EPISODES_FILE, ERRORS_FILE, SWEEP_FILE, LOCK_FILE, MCAP_DIR, EPISODES_FILE + CUT_SUFFIX)
    for name, entry in sorted(entries.items()):
        if name in own or name.endswith(OWN_SUFFIXES):
            _refuse_link(entry)
            if name != MCAP_DIR and entry.is_dir():  # the OS's "Is a directory" named no option
                raise PipelineError(f"{entry} is a directory where the sweep keeps a file; remove it")
            if name != MCAP_DIR and not entry.is_file():  # a pipe's read or write waits for good
                raise PipelineError(
                    f"{entry} is not a regular file (a device or a pipe) where the sweep keeps a file; "
                    "remove it"
                )
    if (out / MCAP_DIR).is_dir():
        for root, dirs, files in os.walk(out / MCAP_DIR):  # a link is listed, never followed
            for name in sorted(dirs + files):
                _refuse_link(Path(root) / name)


def _refuse_link(path: Path) -> None:
    if path.is_symlink():
        raise PipelineError(
            f"{path} is a symbolic link; a sweep writes only its own files: remove the link or choose "
            "another --out"
        )


@contextlib.contextmanager
def sweep_lock(out: Path, made: bool = False) -> Iterator[None]:
    """Refuse a second sweep writing the same directory (its records would interleave). ``made``: the caller
    made ``out`` for this sweep, which is removed again when the sweep is refused or stopped before writing
    anything there but the lock (a --reuse refused for its source's log had left the empty folder)."""
    import fcntl

    with open(out / LOCK_FILE, "w", encoding="utf-8") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise PipelineError(
                f"another sweep is writing to {out}; wait for it or choose another --out"
            ) from None
        except OSError as exc:  # ENOLCK (an NFS mount without its lock daemon), EOPNOTSUPP: not a bug of ours
            raise PipelineError(
                f"cannot lock {out / LOCK_FILE} ({exc.strerror}): the file system of --out does not lock "
                "files (an NFS mount without its lock daemon?), which keeps a second sweep from writing the "
                "same directory; choose an --out on one that does"
            ) from None
        try:
            yield
        except BaseException:
            # its own error is the one to say: a folder that cannot go is left as it is
            with contextlib.suppress(OSError):
                if made and [entry.name for entry in out.iterdir()] == [LOCK_FILE]:
                    (out / LOCK_FILE).unlink()  # while held: a sweep that opened it meanwhile is refused
                    out.rmdir()
            raise
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)
