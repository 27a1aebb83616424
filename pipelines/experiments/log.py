"""A sweep directory's durable episode log (``<out>/episodes.jsonl``); the lock that keeps it to one sweep and
the check of the folder are pipelines.experiments.sweep_folder.

Durability. Only the driver (pipelines.experiments.sweep) writes the sweep directory. Each finished episode
becomes one JSON line of ``<out>/episodes.jsonl``, written with one ``write`` and made durable (flush + fsync)
before the next is taken, keyed by ``cell/scenario/seed``. A rerun reads the file, skips every key already
there and runs the rest, so no episode is repeated or lost however often the sweep is killed. A kill can tear
at most the last line (a partial write); loading drops it (truncating the file back to its last complete line)
and its episode runs again. A lock file refuses a second sweep writing the same directory at the same time.
The names of the directory's other files are here too, so that every module names them alike.
"""

from __future__ import annotations

import functools
import itertools
import json
import os
import stat
import sys
import warnings
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from pipelines.errors import DroppedLineWarning, PipelineError
from pipelines.experiments.record_checks import DAMAGED, check_sweep_record
from pipelines.plain_json import plain

if TYPE_CHECKING:
    from pipelines.experiments.tasks import EpisodeTask

EPISODES_FILE: Final[str] = "episodes.jsonl"
ERRORS_FILE: Final[str] = "errors.jsonl"
SWEEP_FILE: Final[str] = "sweep.json"
LOCK_FILE: Final[str] = ".sweep.lock"
MCAP_DIR: Final[str] = "mcap"


class EpisodeLog:
    """Append-only JSON-lines file of episode records, one per key."""

    def __init__(
        self, path: Path, check: Callable[[dict[str, Any], str], None] | None = None, damaged: str = DAMAGED
    ):
        """``check(record, "file:line")`` raises for a record of the wrong shape (``episode_log``'s does);
        ``damaged``: what a refusal of a damaged line says to do (another sweep's log is not ours to edit)."""
        self.path = Path(path)
        self.check = check
        self.damaged = damaged

    def load(self, repair: bool = True) -> dict[str, dict[str, Any]]:
        """Every complete record by key, as ``scan`` reads them."""
        return {record["key"]: record for _, _, record in self.scan(repair)}

    def scan(self, repair: bool = True) -> Iterator[tuple[int, bytes, dict[str, Any]]]:
        """Every complete record, checked, in the file's order, with its line and the line's offset: what
        ``load`` holds, a record at a time (a report of a million records held 4.1 GB of them). A torn tail
        (bytes after the last newline, or a last line that is not JSON) is ignored and, with ``repair`` (only
        the sweep holding the lock may), cut off the file once every record was read, so that its episode
        runs again; a bad line elsewhere or a repeated key means the file was damaged or edited, and is
        refused. Read a line at a time."""
        if not self.path.exists():
            return
        if not self.path.is_file():  # a pipe's open waits for a writer; /dev/zero is one endless line
            raise PipelineError(
                f"{self.path}: is not a regular file (a device or a pipe); a sweep keeps its records in one"
            )
        seen: set[int] = set()  # each key's hash: the keys themselves were ~100 B a record
        good_end = size = 0
        bad: tuple[int, Exception] | None = None  # a line that is not JSON: fine only as the last one
        with open(self.path, "rb") as f:
            for number, line in enumerate(f, start=1):
                offset = size
                size += len(line)
                if not line.endswith(b"\n"):
                    break  # only what a newline ends was fully written
                if bad is not None:
                    raise PipelineError(
                        f"{self.path}:{bad[0]}: not a JSON record ({bad[1]}); {self.damaged}"
                    ) from None
                try:
                    record = json.loads(line) if line.strip() else None
                # json's parser recurses: a line nested deeper than the stack is garbage too, as is an
                # integer literal past Python's 4300 digits (a ValueError, no JSONDecodeError)
                except (ValueError, RecursionError) as exc:
                    bad = (number, exc)
                    continue
                if record is not None:
                    key = record.get("key") if isinstance(record, dict) else None
                    if not isinstance(key, str):
                        raise PipelineError(f"{self.path}:{number}: record has no 'key'; {self.damaged}")
                    if self.check is not None:
                        self.check(record, f"{self.path}:{number}")
                    if hash(key) in seen and self._key_before(key, number):
                        raise PipelineError(
                            f"{self.path}:{number}: a second record for {key!r}; {self.damaged}"
                        )
                    seen.add(hash(key))
                    yield offset, line, record
                good_end += len(line)
        if repair and good_end < size:
            if bad is not None:
                self._keep_cut(good_end, bad)
            with open(self.path, "r+b") as f:
                f.truncate(good_end)
                f.flush()
                os.fsync(f.fileno())

    def scan_shown(
        self, progress: bool | None, repair: bool = True, name: str | None = None
    ) -> Iterator[tuple[int, bytes, dict[str, Any]]]:
        """``scan``, with a bar of the log's bytes read when ``progress`` (None: on a terminal only), named
        "reading ``name``" (the file's name by default): a resume, a report or ``config show --from-sweep``
        read ~10,000 records a second, and spent a minute and more on a large log before their first word."""
        from predictors.progress import progress_bar

        total = self.path.stat().st_size if self.path.is_file() else 0
        bar = progress_bar(
            total=total,
            show=progress,
            desc=f"reading {name or self.path.name}",
            unit="B",
            unit_scale=True,
            file=sys.stderr,
            leave=False,
        )
        try:
            for offset, line, record in self.scan(repair):
                bar.update(len(line))
                yield offset, line, record
        finally:
            bar.close()

    def _keep_cut(self, start: int, bad: tuple[int, Exception]) -> None:
        """Keep a whole last line that is no record, about to be cut off, in ``<log>.cut``, and say so: a
        crash can leave one, but so can an edit, lost without a word (a torn line without newline is not)."""
        kept = self.path.with_name(self.path.name + CUT_SUFFIX)
        try:  # never through a link planted there (check_sweep_directory refuses one first)
            fd = os.open(kept, os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NOFOLLOW, 0o666)
            with os.fdopen(fd, "ab") as f, open(self.path, "rb") as source:
                source.seek(start)
                f.write(source.read())
                f.flush()
                os.fsync(f.fileno())
        except OSError as exc:
            raise PipelineError(f"{kept}: cannot write there ({exc.strerror}); remove it") from None
        warnings.warn(
            f"{self.path}:{bad[0]}: the last line is no JSON record ({bad[1]}), as a crash while writing can "
            f"leave; cut off (an episode it held runs again) and kept in {kept}",
            DroppedLineWarning,
            stacklevel=3,
        )

    def _key_before(self, key: str, number: int) -> bool:
        """Whether a line before line ``number`` is a record of ``key``: two keys' hashes may be equal."""
        with open(self.path, "rb") as f:
            for line in itertools.islice(f, number - 1):
                record = json.loads(line) if line.strip() else None  # read once already: JSON all
                if isinstance(record, dict) and record.get("key") == key:
                    return True
        return False

    def append(self, record: dict[str, Any]) -> tuple[int, bytes]:
        """Writes ``record`` as the log's last line; returns that line and its offset, as ``scan`` gives
        them. A torn last line no scan cut off (errors.jsonl is never cut) is ended first: appended to, it
        took this record into a line that reads as neither."""
        data = self._line(record)
        try:
            with open(self.path, "a+b") as f:
                offset = os.fstat(f.fileno()).st_size  # one writer: the sweep holding the lock
                if offset and os.pread(f.fileno(), 1, offset - 1) != b"\n":
                    f.write(b"\n")
                    offset += 1
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            if not offset:
                _sync_name(self.path)
        except OSError as exc:  # a full disk, a quota, `ulimit -f`: a torn last line, which a resume cuts
            raise self._not_appended(f"the record of {record.get('key')!r}", exc, "it") from None
        return offset, data

    def extend(self, records: Iterable[dict[str, Any]]) -> None:
        """Writes ``records`` as the log's last lines, synced once (``append`` syncs each line): a stop
        halfway leaves whole lines and at most a torn last one, which a resume cuts."""
        try:
            with open(self.path, "ab") as f:
                new = not os.fstat(f.fileno()).st_size
                for record in records:
                    f.write(self._line(record))
                f.flush()
                os.fsync(f.fileno())
            if new:
                _sync_name(self.path)
        except OSError as exc:
            raise self._not_appended("records", exc, "them") from None

    def _not_appended(self, what: str, exc: OSError, it: str) -> PipelineError:
        return PipelineError(
            f"{self.path}: could not append {what} ({exc.strerror or exc}); the episodes recorded before "
            f"{it} are kept: free space and run the same sweep again to resume"
        )

    def _line(self, record: dict[str, Any]) -> bytes:
        try:
            return (json.dumps(plain(record), allow_nan=False, separators=(",", ":")) + "\n").encode()
        except (TypeError, ValueError) as exc:  # the workers check their records (worker.check_json)
            key = record.get("key") if isinstance(record, dict) else None
            raise PipelineError(f"{self.path}: cannot write the record of {key!r} as JSON ({exc})") from None


def _sync_name(path: Path) -> None:
    """The folder of a log whose first line was just synced, synced once: the file's data is on disk, but
    on a strict POSIX file system its name (the entry the open made) may not be, and a power loss could
    lose every episode of the sweep with it. Later lines add no entry, so need no folder sync."""
    from predictors.durable import sync_folder  # not at import: the predictors package loads casadi

    sync_folder(path.parent)


def write_whole(path: Path, data: bytes) -> None:
    """``data`` into ``path`` in one durable rename (``replace_durably``): a stop or a full disk halfway
    leaves the file as it was, and no ``.part``; a power loss, the file whole (sweep.json, a kept
    recording)."""
    from predictors.durable import replace_durably  # not at import: the predictors package loads casadi

    tmp = path.with_suffix(path.suffix + PART_SUFFIX)
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        replace_durably(tmp, path)
    finally:  # stopped before the replace: the half-written file is nobody's
        tmp.unlink(missing_ok=True)


def error_keys(out: Path) -> set[str]:
    """The keys of the episodes ``<out>/errors.jsonl`` holds (episodes that raised, each entry a line; a
    rerun that retries one appends again). A line that is no entry (a torn tail) is passed over: the keys only
    order a rerun's episodes."""
    keys: set[str] = set()
    path = out / ERRORS_FILE
    if not path.is_file():
        return keys
    with open(path, "rb") as f:
        for line in f:
            try:
                entry = json.loads(line)
            # nested past the stack, or an integer past 4300 digits (a ValueError, no JSONDecodeError)
            except (ValueError, RecursionError):
                continue
            if isinstance(entry, dict) and isinstance(entry.get("key"), str):
                keys.add(entry["key"])
    return keys


def mcap_path(out: Path, task: EpisodeTask) -> Path:
    """Where sweep ``out`` keeps the MCAP recording of ``task``'s episode (``--record``)."""
    return out / MCAP_DIR / task.cell.key / f"{task.scenario}_seed{task.seed:06d}.mcap"


def episode_log(out: Path, damaged: str = DAMAGED) -> EpisodeLog:
    """A sweep directory's episodes.jsonl, every line checked to be a record the report can read."""
    check = functools.partial(check_sweep_record, damaged=damaged)
    return EpisodeLog(out / EPISODES_FILE, check=check, damaged=damaged)


def sweep_of_recordings(path: Path, marker: str = EPISODES_FILE) -> Path | None:
    """The sweep folder DIR whose recordings ``path`` is among (DIR/mcap, DIR/mcap/CELL, or a file in one),
    DIR holding the file ``marker``; None for a path outside every sweep's recordings."""
    here = path.resolve()
    for up in [here, *here.parents][:3]:
        if up.name == MCAP_DIR and (up.parent / marker).is_file():
            return up.parent
    return None


def read_json_file(path: Path, what: str, advice: str = "") -> Any:
    """``path``'s JSON document, or a PipelineError "PATH: not WHAT (the reason)ADVICE" for one that cannot
    be read, is not text or not JSON, or nests too deeply. A key given twice is refused (json kept the last
    without a word): a sweep that then rewrote sweep.json dropped what the first held, a run's record."""
    from predictors.errors import DuplicateKey, unique_keys

    try:
        return json.loads(path.read_text(encoding="utf-8"), object_pairs_hook=unique_keys)
    except DuplicateKey as exc:
        raise PipelineError(f"{path}: {exc}{advice}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError, ValueError) as exc:
        raise PipelineError(f"{path}: not {what} ({type(exc).__name__}: {str(exc)[:120]}){advice}") from None


def read_sweep_file(
    path: Path,
    hint: str = "; restore it, or move it away (the episodes it listed are then kept as runs of unknown "
    "code; a new --out starts afresh)",
) -> dict[str, Any]:
    """sweep.json as written by ``run_sweep`` (an object with a list of runs), or an error naming it (and
    ending with ``hint``). One larger than a zoo's documents may be is refused unread: a run line is a few
    kB, and a file of gigabytes (not a sweep's) took the memory."""
    from predictors.checkpoint import MAX_DOCUMENT_BYTES

    try:
        status = path.stat()
    except OSError:  # a missing or unreachable file: read_json_file says so
        status = None
    if status is not None and not stat.S_ISREG(status.st_mode):  # a pipe's read waits for good
        raise PipelineError(
            f"{path}: not a sweep file (not a regular file: a folder, a device or a pipe){hint}"
        )
    size = 0 if status is None else status.st_size
    if size > MAX_DOCUMENT_BYTES:
        raise PipelineError(
            f"{path}: {size} bytes, more than the {MAX_DOCUMENT_BYTES} a sweep file may have{hint}"
        )
    meta = read_json_file(path, "a sweep file", hint)
    if not (isinstance(meta, dict) and isinstance(meta.get("runs", []), list)):
        raise PipelineError(f"{path}: not a sweep file (expected an object with a list of runs)")
    return meta


# What a sweep writes at the top of its directory besides the names above (and its report, sweep_folder's
# OWN_SUFFIXES): the temporary files replaced into place (".part"), a cut line kept (".cut")
PART_SUFFIX: Final[str] = ".part"
CUT_SUFFIX: Final[str] = ".cut"  # episodes.jsonl.cut: a last line a resume cut off (EpisodeLog._keep_cut)
