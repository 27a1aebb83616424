"""Errors a user can cause through the simulator (bad scenario, bad sizes); the CLI prints them plainly. And
the warning of a layout that runs but is probably not what was meant. And the one check of a number a setting
takes (``real_number``, ``whole_number``), so that every settings class accepts and refuses the same values.
And ``counted``, how a message counts robots, humans or pedestrians.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable

import numpy as np


class SimulationError(ValueError):
    """Base class of the user-facing errors raised by `crowdsim`."""


def counted(n: int, noun: str, plural: str = "") -> str:
    """ "1 robot", "3 robots", "0 pedestrians" (``plural``, when not the noun and an s: "1 entry", "2
    entries"): the simulator's refusals said "the episode's 1 robots", where runs of one robot or one human
    are allowed. crowdsim's own: the pipelines' ``predictors.text_table.counted`` is out of its reach
    (crowdsim imports nothing else of the project, tests/test_layering.py)."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


def got(value: float) -> str:
    """A refused number as its refusal names it: ``:g`` where that reads back as the value, else in full, so
    that a value just past a bound is not rounded onto it ('must be at most 10 m, got 10' of 10.000001)."""
    text = f"{value:g}"
    return text if float(text) == value else repr(float(value))


def refuse_bools(where: str, **values: object) -> None:
    """SimulationError for a bool given as a length, a speed or a step: Python takes True for 1, so
    ``orca_velocities(..., dt=True)`` ran a 1 s step and ``radii=True`` a 1 m disc without a word. A type
    test per value, not a conversion, so the simulator's calls (a float or a float array) pay well under a
    microsecond; a list, a tuple or an object array is looked into, as numpy turns ``[True, 0.3]`` into
    ``[1.0, 0.3]``."""
    for name, value in values.items():
        if type(value) is not float and _holds_bool(value):  # a plain float, the common case, at once
            raise SimulationError(f"{where}: {name} must be a number, not a bool, got {value!r}")


def _holds_bool(value: object) -> bool:
    if isinstance(value, np.ndarray):
        if value.dtype != object:
            return value.dtype == np.bool_
        value = value.ravel().tolist()  # an object array's items are the Python objects it was given
    if isinstance(value, list | tuple):
        return any(_holds_bool(item) for item in value)
    return isinstance(value, bool | np.bool_)


def texts_or_bools(raw: np.ndarray) -> str | None:
    """What ``raw`` holds in place of numbers that numpy's float conversion reads as numbers ("3" as 3.0,
    True as 1.0): its dtype for an array of texts or booleans ("<U3", "bool"), the type of an object array's
    first text or boolean ("str"); None when it holds none."""
    if raw.dtype.kind in "bSU":
        return str(raw.dtype)
    if raw.dtype == object:
        for item in raw.flat:
            if isinstance(item, str | bytes | bool | np.bool_):
                return type(item).__name__
    return None


class LayoutWarning(UserWarning):
    """A layout the simulator runs but that starts agents in contact (``CrowdEnv.reset_layout``)."""


def too_crowded(
    human: int, n_humans: int, scenario: str, n_robots: int, draws: int, min_dist: float
) -> SimulationError:
    """The error of a layout whose rejection sampling ran dry (``human`` counts from 0). It states the
    distance the draws had to keep and what sets it: with one human and one robot, "use fewer agents" was
    no advice when a large spawn_separation was the cause."""
    return SimulationError(
        f"could not place human {human + 1} of n_humans={n_humans} in scenario {scenario!r} with "
        f"{counted(n_robots, 'robot')} after {counted(draws, 'draw')}, each start and goal {min_dist:g} m "
        "apart (2 x radius + spawn_separation); use fewer agents, or a smaller spawn_separation or radius"
    )


def real_number(where: str, value: object, expected: str, ok: Callable[[float], bool]) -> float:
    """``value`` as a plain float, when it is a real number that ``ok`` accepts; else SimulationError
    "``where`` must be ``expected``, got ``value``". numpy's scalars count (np.float32(0.4) is a time step)
    and bools do not (True is no length); a plain float keeps numpy's types out of the simulator's
    arithmetic."""
    plain = _plain_float(value)
    if plain is None or not ok(plain):
        raise SimulationError(f"{where} must be {expected}, got {value!r}")
    return plain


def seconds(where: str, value: object) -> float:
    """A time step or a duration as a plain float, when it is a real number (a Fraction too, as the settings
    take it), else SimulationError "``where`` must be a real number of seconds": a Decimal or a text went on
    to numpy's TypeError ("unsupported operand type(s) for /: 'float' and 'decimal.Decimal'"). Its bounds
    are the caller's to check."""
    return value if type(value) is float else real_number(where, value, "a real number of seconds", _any)


def _any(_: float) -> bool:
    return True


def whole_number(where: str, value: object, expected: str, least: int) -> int:
    """``value`` as a plain int, when it is an integer (numpy's too, not a bool) of at least ``least``; else
    SimulationError "``where`` must be ``expected``, got ``value``"."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < least:
        raise SimulationError(f"{where} must be {expected}, got {value!r}")
    return int(value)


def _plain_float(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    try:
        return float(value)
    except OverflowError:  # an integer past the largest float
        return None
