"""What ``crowdmpc sweep``'s report takes of --out's episodes.jsonl (``LogRead``), read a record at a time
as the sweep appends them or on its own (``read_log``), and episodes.csv's rows, each record read again at
its offset (``episode_rows``)."""

from __future__ import annotations

import dataclasses
import json
import sys
import zlib
from collections.abc import Callable, Collection, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipelines.errors import PipelineError
from pipelines.experiments.cell_columns import FLOATS, CellColumns, Column
from pipelines.experiments.run_lines import run_number

if TYPE_CHECKING:
    from pipelines.experiments.sweep_config import SweepConfig
    from pipelines.experiments.tasks import Cell, EpisodeTask


@dataclass
class LogRead:
    """What the report takes of a sweep's log, read a record at a time: a report that held every record
    (its config left out) held 3.7 KB an episode, 4.1 GB at a million (benchmarks/sweep_log_scale.py)."""

    held: int = 0  # records in the log
    planned: int = 0  # of those, the plan's episodes
    cells: set[str] = dataclasses.field(default_factory=set)  # the cells of those
    # of the plan's episodes of ``cells``' cells (those the report tabulates), by cell key
    columns: dict[str, CellColumns] = dataclasses.field(default_factory=dict)
    cpu: Column = dataclasses.field(
        default_factory=lambda: Column(FLOATS)
    )  # each planned record's cpu_s that is set
    planned_keys: Collection[str] = ()  # the plan's episodes' keys
    tabulated: Collection[str] = ()  # the keys of the cells the report tabulates
    runs: set[int | None] = dataclasses.field(default_factory=set)  # the runs that made the tabulated ones

    @classmethod
    def of_plan(cls, cells: tuple[Cell, ...], tasks: list[EpisodeTask]) -> LogRead:
        """Nothing read yet, of the plan of ``tasks`` tabulated as ``cells``: ``add`` each record."""
        return cls(planned_keys={t.key for t in tasks}, tabulated={c.key for c in cells})

    def add(self, offset: int, line: bytes, record: dict[str, Any]) -> None:
        """The log's record ``record``, its line ``line`` at byte ``offset`` (``EpisodeLog.scan``'s)."""
        self.held += 1
        if record["key"] not in self.planned_keys:
            return
        self.planned += 1
        self.cells.add(record["cell"])
        if record.get("cpu_s") is not None:
            self.cpu.append(record["cpu_s"])
        if record["cell"] in self.tabulated:
            self.columns.setdefault(record["cell"], CellColumns()).add(record, offset, zlib.crc32(line))
            self.runs.add(run_number(record))


def read_log(
    config: SweepConfig,
    cells: tuple[Cell, ...],
    tasks: list[EpisodeTask],
    also: Callable[[dict[str, Any]], None] | None = None,
) -> LogRead:
    """--out's episodes.jsonl as the report reads it, checked as a sweep loads it; ``also``: given each
    record of the plan too (those the report is of)."""
    from pipelines.experiments.log import episode_log

    log = LogRead.of_plan(cells, tasks)
    for offset, line, record in episode_log(config.out).scan_shown(config.progress, repair=False):
        log.add(offset, line, record)
        if also is not None and record["key"] in log.planned_keys:
            also(record)
    return log


def episode_rows(
    path: Path, cells: tuple[Cell, ...], log: LogRead, progress: bool | None = False
) -> Iterator[dict[str, Any]]:
    """episodes.csv's rows, in the plan's order (report.episode_rows'), each made of its record read again
    from the log at its offset: a line that changed since (the log was replaced) is refused. ``progress``: a
    bar of the rows (None: on a terminal only), read again at ~25,000 a second, 40 s at a million."""
    from pipelines.experiments.report import episode_row
    from predictors.progress import progress_bar

    # each cell once, at its last place and with its last label, as report.episode_rows sorts and labels
    place = {c.key: i for i, c in enumerate(cells)}
    label = {c.key: c.method for c in cells}
    if not log.columns:  # no episode to read: a new sweep whose every episode raised has no log to open
        return
    total = sum(len(column) for column in log.columns.values())
    bar = progress_bar(
        total=total, show=progress, desc="writing episodes.csv", unit="ep", file=sys.stderr, leave=False
    )
    with open(path, "rb") as f, bar:
        for key in sorted(place, key=place.__getitem__):
            for offset, crc in log.columns[key].lines() if key in log.columns else ():
                f.seek(offset)
                line = f.readline()
                if zlib.crc32(line) != crc:
                    raise PipelineError(
                        f"{path} changed while the report read it (the record at byte {offset}); report again"
                    )
                bar.update(1)
                yield episode_row(json.loads(line), label[key])
