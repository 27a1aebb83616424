"""A cell's episodes as the report reads them, a column per figure: what a large sweep's report holds.

The report used to hold every record of the log as a parsed dict (3.7 KB an episode, its config left out:
4.1 GB at a million episodes, benchmarks/sweep_log_scale.py). ``CellColumns`` keeps, of each record, only the
fields the cell's summary reads (pipelines.experiments.summary), each in a machine array while its values are
of the array's kind (a float, an integer, a boolean, or null), and where the record's line lies in the log
(episodes.csv reads the lines again, one at a time: pipelines.commands.sweep_log_read). A column whose values
stop fitting its array (a float where an integer was, an integer past 64 bits) becomes a plain list, so that
every value reads back exactly as the record held it, and every figure of the report is the same.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Iterable, Iterator, Mapping
from typing import Any, Final

from crowdsim.metrics import ADDED_FLAGS

# The fields a cell's summary reads (summary.summarize_cell, safety_report.safety_figures), by their kind.
FLOATS: Final[str] = "d"
COUNTS: Final[str] = "q"
FLAGS: Final[str] = "b"
METRIC_COLUMNS: Final[dict[str, str]] = {
    **dict.fromkeys(("success", "collision", "contact", "discomfort"), FLAGS),
    **dict.fromkeys(ADDED_FLAGS, FLAGS),  # the flags added after the first records, counted per cell
    **dict.fromkeys(("travel_time", "min_distance"), FLOATS),
    **dict.fromkeys(
        ("n_steps", "collision_steps", "contact_steps", "discomfort_steps", "robot_contact_steps"), COUNTS
    ),
}
SOLVER_COLUMNS: Final[dict[str, str]] = {
    **dict.fromkeys(("steps", "fallback_steps"), COUNTS),
    **dict.fromkeys(("total_ms", "median_ms", "p95_ms", "mean_iterations"), FLOATS),
}
_INT64_MIN: Final[int] = -(2**63)  # a count's null: no count is negative
_NOT_OF_KIND: Final[object] = object()


def _encode(kind: str, value: Any) -> Any:
    """``value`` as the array of ``kind`` holds it (null: a number no value of the kind takes), or
    ``_NOT_OF_KIND``."""
    if kind == FLOATS:
        if value is None:
            return math.nan
        return value if type(value) is float and not math.isnan(value) else _NOT_OF_KIND
    if kind == COUNTS:
        if value is None:
            return _INT64_MIN
        return value if type(value) is int and _INT64_MIN < value < 2**63 else _NOT_OF_KIND
    if value is None:  # FLAGS
        return -1
    return int(value) if type(value) is bool else _NOT_OF_KIND


def _decode(kind: str, stored: Any) -> Any:
    if kind == FLOATS:
        return None if math.isnan(stored) else stored
    if kind == COUNTS:
        return None if stored == _INT64_MIN else stored
    return None if stored == -1 else bool(stored)


class Column:
    """One field's value in each episode: a machine array (8 bytes a value, 1 for a flag) while the values
    are of its kind, else a list of the values themselves."""

    __slots__ = ("kind", "values")

    def __init__(self, kind: str):
        self.kind = kind
        self.values: array[Any] | list[Any] = array(kind)

    def append(self, value: Any) -> None:
        if isinstance(self.values, list):
            self.values.append(value)
            return
        stored = _encode(self.kind, value)
        if stored is _NOT_OF_KIND:
            self.values = [_decode(self.kind, v) for v in self.values]
            self.values.append(value)
        else:
            self.values.append(stored)

    def __getitem__(self, i: int) -> Any:
        stored = self.values[i]
        return stored if isinstance(self.values, list) else _decode(self.kind, stored)

    def __len__(self) -> int:
        return len(self.values)


class _Part:
    """An episode's metrics or solver figures, read from the columns as the record's mapping was read."""

    __slots__ = ("_columns", "_i")

    def __init__(self, columns: Mapping[str, Column], i: int):
        self._columns = columns
        self._i = i

    def __getitem__(self, name: str) -> Any:
        return self._columns[name][self._i]

    def get(self, name: str, default: Any = None) -> Any:
        column = self._columns.get(name)
        return default if column is None else column[self._i]


class CellColumns:
    """One cell's episodes, in the order they were added (the log's): seed, scenario, the summary's fields,
    and, for a record read from the log, its line's offset and CRC-32 (``lines``)."""

    def __init__(self) -> None:
        self.seeds = Column(COUNTS)
        self._scenario_codes: dict[Any, int] = {}  # a sweep has two scenarios: a byte-size code each
        self._scenarios: list[Any] = []
        self.scenario_codes: array[int] = array("i")
        self.metrics = {name: Column(kind) for name, kind in METRIC_COLUMNS.items()}
        self.solver = {name: Column(kind) for name, kind in SOLVER_COLUMNS.items()}
        self.offsets: array[int] = array("q")
        self.crcs: array[int] = array("L")
        self.calibrations: set[str] = set()  # where the cell's calibrated margins came from (a few at most)

    def add(self, record: Mapping[str, Any], offset: int | None = None, crc: int = 0) -> None:
        """``record``'s fields (a field it lacks is null, as the summary's ``get`` reads it); ``offset`` and
        ``crc``: its line in the log."""
        self.seeds.append(record["seed"])
        scenario = record["scenario"]
        if scenario not in self._scenario_codes:
            self._scenario_codes[scenario] = len(self._scenarios)
            self._scenarios.append(scenario)
        self.scenario_codes.append(self._scenario_codes[scenario])
        for part, columns in (("metrics", self.metrics), ("solver", self.solver)):
            values = record[part]
            for name, column in columns.items():
                column.append(values.get(name))
        self.calibrations.update(calibration_texts([record]))
        if offset is not None:
            self.offsets.append(offset)
            self.crcs.append(crc)

    def __len__(self) -> int:
        return len(self.scenario_codes)

    def scenario(self, i: int) -> Any:
        return self._scenarios[self.scenario_codes[i]]

    def episodes(self) -> list[dict[str, Any]]:
        """The episodes as records for ``summary.summarize_cell``: seed, scenario, metrics and solver (their
        figures read from the columns), in the order they were added. One cell's at a time."""
        return [
            {
                "seed": self.seeds[i],
                "scenario": self.scenario(i),
                "metrics": _Part(self.metrics, i),
                "solver": _Part(self.solver, i),
            }
            for i in range(len(self))
        ]

    def plan_order(self) -> list[int]:
        """The episodes' indices by seed and scenario, the plan's order (summarize_cell's and episodes.csv's
        sort, stable as theirs)."""
        return sorted(range(len(self)), key=lambda i: (self.seeds[i], str(self.scenario(i))))

    def lines(self) -> Iterator[tuple[int, int]]:
        """(offset, CRC-32) of each episode's line in the log, in the plan's order."""
        for i in self.plan_order():
            yield self.offsets[i], self.crcs[i]


def calibration_texts(records: Iterable[Mapping[str, Any]]) -> set[str]:
    """Where the calibrated margins of ``records`` came from (``pipelines.loop.margins.calibration_text`` of
    each record's ``config.margins.calibration``): none for margins without a calibration, or records
    without their config."""
    from pipelines.loop.margins import calibration_text

    made = (((r.get("config") or {}).get("margins") or {}).get("calibration") for r in records)
    return {calibration_text(c) for c in made if c}
