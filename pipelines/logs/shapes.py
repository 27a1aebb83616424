"""What ``crowdmpc review`` needs of a recorded message and of the episode metadata, checked on reading.

A message that decodes as JSON but lacks what the review reads (a field, a type, an array's shape) is reported
by ``pipelines.logs.reader`` and left out, so that a hostile or foreign file cannot crash the summary, the
table or the plots. This is deliberately less than the channel's schema: only the fields the review reads,
so that a recording from another crowdmpc version (extra fields) still reviews; ``review --check`` holds every
message to the schema stored in its file.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any, Final

import numpy as np

from crowdsim.env_config import ENV_BOUNDS
from crowdsim.scenarios import MAX_HUMANS, MAX_ROBOTS

# -- values ------------------------------------------------------------------------------------------------


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _is_real(x: Any) -> bool:
    """A finite JSON number (json.loads also reads NaN and Infinity)."""
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def _array_problem(value: Any, ndim: int) -> str | None:
    """``value`` is a rectangular array of numbers (null allowed) with ``ndim`` axes, the last of size 2."""
    try:
        array = np.asarray(value, dtype=float)
    except (ValueError, TypeError, OverflowError, RecursionError):
        return "is not a rectangular array of numbers"
    if array.size == 0 and array.ndim == ndim - 1 and array.shape[-1] == 0:
        return None  # no agents: json has no shape for (0, 2) or (H, 0, 2), numpy reads (0,) or (H, 0)
    if array.ndim != ndim or array.shape[-1] != 2:
        return f"has shape {array.shape}, expected {ndim} axes ending in 2 (x, y)"
    return None


def _fields(message: Any, checks: Mapping[str, Callable[[Any], str | None]]) -> str | None:
    if not isinstance(message, dict):
        return f"a JSON {type(message).__name__}, expected an object"
    for name, check in checks.items():
        if name not in message:
            return f"lacks {name!r}"
        problem = check(message[name])
        if problem:
            return f"{name!r} {problem}"
    return None


def _int(x: Any) -> str | None:
    return None if _is_int(x) else f"is {x!r}, expected an integer"


def _real(x: Any) -> str | None:
    return None if _is_real(x) else f"is {x!r}, expected a finite number"


def _real_or_null(x: Any) -> str | None:
    return None if x is None or _is_real(x) else f"is {x!r}, expected a finite number or null"


def _text(x: Any) -> str | None:
    return None if isinstance(x, str) else f"is {x!r}, expected a string"


def _text_or_null(x: Any) -> str | None:
    return None if x is None or isinstance(x, str) else f"is {x!r}, expected a string or null"


def _object(x: Any) -> str | None:
    return None if isinstance(x, dict) else f"is a JSON {type(x).__name__}, expected an object"


def _points(x: Any) -> str | None:  # (K, 2)
    return _array_problem(x, 2)


def _tracks(x: Any) -> str | None:  # (A, H, 2) or (H, N, 2)
    return _array_problem(x, 3)


_FLAGS: Final = ("success", "collision", "contact", "discomfort", "timeout")
_NUMBERS: Final = ("travel_time", "min_distance")


def _metrics(x: Any) -> str | None:
    """The episode's metrics as the review adds them up: its flags booleans, its travel time and distance
    numbers or null, a success with its travel time. A hand-made "success": "yes" counted as a success and
    passed --check, a NaN travel time made the folder's mean unknown, where compare refused both."""
    if not isinstance(x, dict):
        return _object(x)
    for name in _FLAGS:
        if name in x and not isinstance(x[name], bool):
            return f"{name!r} is {x[name]!r}, expected true or false"
    for name in _NUMBERS:
        if name in x and (problem := _real_or_null(x[name])):
            return f"{name!r} {problem}"
    if x.get("success") is True and "travel_time" in x and x["travel_time"] is None:
        return "a success without its travel time"
    # what ended the episode is told from it (pipelines.logs.ending): -3 or true read as a loop's early stop
    if "n_steps" in x and not (_is_int(x["n_steps"]) and x["n_steps"] >= 0):
        return f"'n_steps' is {x['n_steps']!r}, expected a count of steps (an integer, 0 or more)"
    return None


_Checks = dict[str, Callable[[Any], str | None]]
_STATE: Final[_Checks] = {"time": _real, "step": _int, "positions": _points, "goals": _points}
_TRACK: Final[_Checks] = {"time": _real, "step": _int, "positions": _tracks}
_REQUIRED: Final[dict[str, _Checks]] = {
    "/robots": _STATE,
    "/humans": _STATE,
    "/mpc/plan": _TRACK,
    "/mpc/prediction": _TRACK,
    "/mpc/solver": {
        "time": _real,
        "step": _int,
        "status": _text,
        "solve_time_s": _real,
        "iterations": _real,
        "potential": _real_or_null,
        "fallback": _text_or_null,
    },
    "/episode/metrics": {"metrics": _metrics},
}


def message_problem(topic: str, message: Any) -> str | None:
    """Why the review cannot use ``message`` (decoded JSON) of ``topic``, or None; other topics pass."""
    checks = _REQUIRED.get(topic)
    return None if checks is None else _fields(message, checks)


# -- metadata ----------------------------------------------------------------------------------------------

_EPISODE_INTS: Final = ("seed", "n_robots", "n_humans")
# the simulator's own bounds on the agents (crowdsim.scenarios): "1000000000 robots" was shown as read
_EPISODE_COUNTS: Final[Mapping[str, int]] = {"n_robots": MAX_ROBOTS, "n_humans": MAX_HUMANS}
_EPISODE_REALS: Final = ("dt", "radius")
# The simulator's own bound on the radius (crowdsim.env_config): a hand-edited radius of 1e300 passed as a
# positive number and kept `review --plot` drawing for over a minute.
_EPISODE_MOST: Final[Mapping[str, tuple[float, str]]] = {"radius": ENV_BOUNDS["radius"]}


def episode_metadata_problems(episode: Mapping[str, str]) -> dict[str, str]:
    """{key: problem} for the values of the "episode" metadata record that the review parses as numbers: the
    integers, and dt and radius as positive numbers, the radius within the simulator's bound."""
    problems = {}
    for key in _EPISODE_INTS:
        if key in episode:
            try:
                count = int(episode[key])
            except ValueError:
                problems[key] = f"{key} = {episode[key]!r} is not an integer"
            else:
                if key in _EPISODE_COUNTS and not 0 <= count <= _EPISODE_COUNTS[key]:
                    problems[key] = f"{key} = {count} is outside the simulator's 0..{_EPISODE_COUNTS[key]}"
    for key in _EPISODE_REALS:
        if key in episode:
            try:
                value = float(episode[key])
            except ValueError:
                value = math.nan
            if not (math.isfinite(value) and value > 0):
                problems[key] = f"{key} = {episode[key]!r} is not a positive number"
            elif key in _EPISODE_MOST and value > _EPISODE_MOST[key][0]:
                most, unit = _EPISODE_MOST[key]
                problems[key] = f"{key} = {episode[key]!r} is beyond the simulator's {most:g} {unit}"
    return problems
