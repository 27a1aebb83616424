"""Writing an episode's outcome into the sweep directory, as the driver (pipelines.experiments.sweep) does for
each one a worker hands back, those a stopped sweep's other workers finished too (sweep_stop): an error to
``errors.jsonl``, or the MCAP log a worker kept and then the record that vouches for it."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any, Protocol

from pipelines.errors import PipelineError
from pipelines.experiments.log import ERRORS_FILE, EpisodeLog, mcap_path, write_whole
from pipelines.experiments.tasks import EpisodeTask
from pipelines.experiments.worker import EpisodeOutcome
from pipelines.loop.interrupt import interrupts_between_steps


class _Counts(Protocol):  # pipelines.experiments.sweep's SweepOutcome, which imports this module
    errors: list[str]
    ran: int


@dataclass(frozen=True)
class OutcomeWriter:
    """Writes each outcome of one run of a sweep (called with it), counting it in ``outcome``."""

    log: EpisodeLog
    outcome: _Counts
    tasks: Mapping[str, EpisodeTask]  # the run's, by key
    run: int  # the run's number in sweep.json, each record's ``run``
    records: Callable[[int, bytes, dict[str, Any]], None] | None  # run_sweep's ``records``
    bar: Any  # the progress bar
    backend: str  # its name, for a backend's answer for an episode it was not given

    def __call__(self, result: EpisodeOutcome) -> None:
        # An interrupt (Ctrl-C; SIGTERM or SIGHUP under terminate_as_interrupt) is held until the outcome is
        # written and counted, as during an episode's step: raised halfway, it lost the record of an episode
        # that had run (its MCAP log written, the record not), and a rerun ran it again.
        with interrupts_between_steps():
            self._write(result)

    def _write(self, result: EpisodeOutcome) -> None:
        out = self.log.path.parent
        task = self.tasks.get(result.key)
        if task is None:  # a backend of one's own (backend_factory) answering for another episode
            raise PipelineError(
                f"{self.backend} backend returned episode {result.key!r}, which it was not given"
            )
        if result.error is not None:
            self.outcome.errors.append(result.key)
            append_error(out, task, result.error)
            self.bar.set_postfix(errors=len(self.outcome.errors), refresh=False)
            return
        if result.record is None:
            raise PipelineError(f"episode {result.key}: the worker returned neither a record nor an error")
        if result.mcap is not None:
            write_atomic(mcap_path(out, task), result.mcap)  # before the record that vouches for it
        # which run of sweep.json, hence which code, made it: a resume by other code keeps the earlier
        # episodes (sweep._note_other_code), and the lines' order alone does not say where one run ends
        offset, line = self.log.append(result.record | {"run": self.run})
        if self.records is not None:
            self.records(offset, line, _read_back(self.log, line, result.key))
        self.outcome.ran += 1
        self.bar.update(1)


def write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        write_whole(path, data)
    except OSError as exc:  # a full disk, a quota, `ulimit -f`: a write's OSError names no file
        raise PipelineError(
            f"{path}: could not write the episode's recording ({exc.strerror or exc}); the episodes recorded "
            "before it are kept: free space and run the same sweep again to resume"
        ) from None


def _read_back(log: EpisodeLog, line: bytes, key: str) -> dict[str, Any]:
    """The record of the line just appended to ``log``, as a scan of the log reads and checks it: a worker's
    record as written (its numpy floats plain floats, its tuples lists), which the report of the run takes
    without reading the log again."""
    record = json.loads(line)
    if log.check is not None:
        log.check(record, f"{log.path} (the record of {key!r} this run appended)")
    return record


def local_time() -> str:
    """Now, local time in ISO 8601's extended form ("2026-12-05T23:41:16+00:00"): strftime's %z gave a basic
    offset, "+0000", which strict ISO readers refuse beside the extended date."""
    return datetime.now().astimezone().isoformat(timespec="seconds")


def append_error(out: Path, task: EpisodeTask, error: str) -> None:
    EpisodeLog(out / ERRORS_FILE).append({"key": task.key, "time": local_time(), "error": error})
