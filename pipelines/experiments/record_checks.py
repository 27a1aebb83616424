"""What a line of a sweep's log must be (``pipelines.experiments.log``'s reads check each): the closed loop's
episode record, its metrics and solver figures of the kinds the report computes with, the sweep's cell fields,
and a key that is its cell, scenario and seed. A line that is none of these is refused as damaged, saying what
to do (``DAMAGED``, or the caller's own advice).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Final

from crowdsim.errors import SimulationError
from pipelines.errors import PipelineError
from pipelines.loop.record import EpisodeRecord

# what a refusal of a damaged log says to do: a line left out is an episode the next sweep runs again
DAMAGED: Final[str] = "the file is damaged: edit out that line (a copy kept) and its episode runs again"


def check_sweep_record(record: dict[str, Any], where: str, damaged: str = DAMAGED) -> None:
    """``check_record``, and a sweep's key is its cell, scenario and seed (``EpisodeTask.key``): a record
    whose seed was edited kept its key, counted as recorded, and paired with another crowd's episode."""
    check_record(record, where, damaged)
    expected = f"{record.get('cell')}/{record['scenario']}/{record['seed']}"
    if record["key"] != expected:
        raise PipelineError(
            f"{where}: record's key {record['key']!r:.120} is not its cell, scenario and seed "
            f"({expected!r:.120}); {damaged}"
        )


def _number(value: Any) -> bool:
    """A finite number: the writer writes NaN and inf as null, and a NaN read back fell in no bin of the
    minimum-distance histogram and made a cell's mean NaN."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


# What the report computes with, as the writer writes it (EpisodeMetrics.as_dict, SolverStats through plain):
# NaN and inf become null. A value of another type would be counted wrongly ("yes" as a success) or stop the
# report with a traceback, so a line holding one is refused like any damaged line.
_KINDS: Final[dict[str, tuple[Callable[[Any], bool], str]]] = {
    "bool": (lambda v: isinstance(v, bool), "a boolean"),
    "bool?": (lambda v: v is None or isinstance(v, bool), "a boolean or null"),
    "count": (_count, "a non-negative integer"),
    "count?": (lambda v: v is None or _count(v), "a non-negative integer or null"),
    "number": (_number, "a finite number"),
    "number?": (lambda v: v is None or _number(v), "a finite number or null"),
    "numbers": (
        lambda v: isinstance(v, list) and all(x is None or _number(x) for x in v),
        "a list of finite numbers (or nulls)",
    ),
}
METRIC_KINDS: Final[dict[str, str]] = {
    **dict.fromkeys(("success", "collision", "contact", "discomfort", "timeout"), "bool"),
    **dict.fromkeys(("travel_time", "min_distance", "min_distance_robots", "min_distance_humans"), "number?"),
    **dict.fromkeys(("path_length", "reach_times"), "numbers"),
    **dict.fromkeys(("discomfort_steps", "n_steps"), "count"),
    **dict.fromkeys(("collision_steps", "contact_steps"), "count?"),  # absent from records before them
    "min_distance_between_steps": "number?",  # these three too
    **dict.fromkeys(("collision_between_steps", "contact_between_steps"), "bool?"),
    "robot_contact": "bool?",  # robot-robot contact (not in the paper): absent from records before it
    "robot_contact_steps": "count?",
    "min_distance_robots_between_steps": "number?",  # and its between-step figures, before them
    "robot_contact_between_steps": "bool?",
}
SOLVER_KINDS: Final[dict[str, str]] = {
    **dict.fromkeys(("steps", "fallback_steps"), "count"),
    "total_ms": "number",
    **dict.fromkeys(("median_ms", "p95_ms", "max_ms", "mean_iterations"), "number?"),
    "max_iterations": "count?",
}


def check_record(record: dict[str, Any], where: str, damaged: str = DAMAGED) -> None:
    """A line the report can read: the closed loop's episode record, the types of its metrics and solver
    figures, and the sweep's cell fields. The seed and scenario are checked here, not by from_dict, which
    takes a null seed (simulate's unseeded episode) and casts both: the report sorts and groups by them."""
    try:
        EpisodeRecord.from_dict(record)
    except (PipelineError, SimulationError) as exc:
        raise PipelineError(f"{where}: {exc}; {damaged}") from None
    except AttributeError as exc:  # metrics or solver a list or a string: from_dict expects mappings
        raise PipelineError(f"{where}: not an episode record ({exc}); {damaged}") from None
    _check_kinds(record["metrics"], METRIC_KINDS, "metrics", where, damaged)
    _check_kinds(record["solver"], SOLVER_KINDS, "solver", where, damaged)
    _check_kinds(record, {"wall_s": "number", "cpu_s": "number?"}, "", where, damaged)
    for name, kind, what in (
        ("cell", str, "a string"),
        ("method", str, "a string"),
        ("index", int, "an integer"),
        ("seed", int, "an integer"),
        ("scenario", str, "a string"),
    ):
        value = record.get(name)
        if not isinstance(value, kind) or isinstance(value, bool):
            raise PipelineError(f"{where}: record's {name!r} is not {what}; {damaged}")


def _check_kinds(values: dict[str, Any], kinds: dict[str, str], part: str, where: str, damaged: str) -> None:
    """Each of ``kinds``' fields of ``values`` (of the record's ``part``) is of its kind (``_KINDS``)."""
    for name, kind in kinds.items():
        is_kind, what = _KINDS[kind]
        if not is_kind(values.get(name)):
            field = f"{part} {name!r}" if part else repr(name)
            raise PipelineError(
                f"{where}: record's {field} is not {what} (got {values.get(name)!r:.40}); {damaged}"
            )
