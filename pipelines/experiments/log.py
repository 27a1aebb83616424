"""A sweep directory's durable episode log (``<out>/episodes.jsonl``) and the lock that keeps it to one sweep.

Durability. Only the driver (pipelines.experiments.sweep) writes the sweep directory. Each finished episode
becomes one JSON line of ``<out>/episodes.jsonl``, written with one ``write`` and made durable (flush + fsync)
before the next is taken, keyed by ``cell/scenario/seed``. A rerun reads the file, skips every key already
there and runs the rest, so no episode is repeated or lost however often the sweep is killed. A kill can tear
at most the last line (a partial write); loading drops it (truncating the file back to its last complete line)
and its episode runs again. A lock file refuses a second sweep writing the same directory at the same time.
The names of the directory's other files are here too, so that every module names them alike.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, Final

from crowdsim.errors import SimulationError
from pipelines.errors import PipelineError
from pipelines.loop.record import EpisodeRecord
from pipelines.plain_json import plain

EPISODES_FILE: Final[str] = "episodes.jsonl"
ERRORS_FILE: Final[str] = "errors.jsonl"
SWEEP_FILE: Final[str] = "sweep.json"
LOCK_FILE: Final[str] = ".sweep.lock"
MCAP_DIR: Final[str] = "mcap"


class EpisodeLog:
    """Append-only JSON-lines file of episode records, one per key."""

    def __init__(self, path: Path, check: Callable[[dict[str, Any], str], None] | None = None):
        """``check(record, "file:line")`` raises for a record of the wrong shape (``episode_log``'s does)."""
        self.path = Path(path)
        self.check = check

    def load(self, repair: bool = True) -> dict[str, dict[str, Any]]:
        """Every complete record by key. A torn tail (bytes after the last newline, or a last line that is not
        JSON) is ignored and, with ``repair`` (only the sweep holding the lock may), cut off the file so that
        its episode runs again; a bad line elsewhere or a repeated key means the file was damaged or edited,
        and is refused."""
        if not self.path.exists():
            return {}
        data = self.path.read_bytes()
        lines = data.split(b"\n")[:-1]  # only what a newline ends was fully written
        records: dict[str, dict[str, Any]] = {}
        good_end = 0
        for number, line in enumerate(lines, start=1):
            try:
                record = json.loads(line) if line.strip() else None
            except (json.JSONDecodeError, UnicodeDecodeError) as exc:
                if number == len(lines):
                    break
                raise PipelineError(
                    f"{self.path}:{number}: not a JSON record ({exc}); the file is damaged"
                ) from None
            if record is not None:
                key = record.get("key") if isinstance(record, dict) else None
                if not isinstance(key, str):
                    raise PipelineError(f"{self.path}:{number}: record has no 'key'; the file is damaged")
                if self.check is not None:
                    self.check(record, f"{self.path}:{number}")
                if key in records:
                    raise PipelineError(
                        f"{self.path}:{number}: a second record for {key!r}; the file is damaged"
                    )
                records[key] = record
            good_end += len(line) + 1
        if repair and good_end < len(data):
            with open(self.path, "r+b") as f:
                f.truncate(good_end)
                f.flush()
                os.fsync(f.fileno())
        return records

    def append(self, record: dict[str, Any]) -> None:
        line = json.dumps(plain(record), allow_nan=False, separators=(",", ":")) + "\n"
        with open(self.path, "ab") as f:
            f.write(line.encode())
            f.flush()
            os.fsync(f.fileno())


def episode_log(out: Path) -> EpisodeLog:
    """A sweep directory's episodes.jsonl, every line checked to be a record the report can read."""
    return EpisodeLog(out / EPISODES_FILE, check=check_record)


def check_record(record: dict[str, Any], where: str) -> None:
    """A line the report can read: the closed loop's episode record and the sweep's cell fields."""
    try:
        EpisodeRecord.from_dict(record)
    except (PipelineError, SimulationError) as exc:
        raise PipelineError(f"{where}: {exc}; the file is damaged") from None
    for name, kind, what in (
        ("cell", str, "a string"),
        ("method", str, "a string"),
        ("index", int, "an integer"),
    ):
        value = record.get(name)
        if not isinstance(value, kind) or isinstance(value, bool):
            raise PipelineError(f"{where}: record's {name!r} is not {what}; the file is damaged")


def read_sweep_file(path: Path) -> dict[str, Any]:
    """sweep.json as written by ``run_sweep`` (an object with a list of runs), or an error naming it."""
    try:
        meta = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError, ValueError) as exc:
        raise PipelineError(
            f"{path}: not a sweep file ({type(exc).__name__}: {str(exc)[:120]}); move it away to start afresh"
        ) from None
    if not (isinstance(meta, dict) and isinstance(meta.get("runs", []), list)):
        raise PipelineError(f"{path}: not a sweep file (expected an object with a list of runs)")
    return meta


@contextlib.contextmanager
def sweep_lock(out: Path) -> Iterator[None]:
    """Refuse a second sweep writing the same directory (its records would interleave)."""
    import fcntl

    with open(out / LOCK_FILE, "w") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise PipelineError(
                f"another sweep is writing to {out}; wait for it or choose another --out"
            ) from None
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)
