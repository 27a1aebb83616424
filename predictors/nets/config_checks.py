"""Checks shared by the nets' frozen configs (``SocialGRUConfig``, ``SocialAttentionConfig``; the oldest,
``SocialLSTMConfig``, keeps its own range messages but shares the type message and the JSON object's reading).

A config comes from a JSON file that anyone can edit, so every field's type and range is checked in
``__post_init__`` before a tensor is allocated: a float, bool or string size would otherwise reach torch (a
traceback) or a comparison (a TypeError), and a huge one would ask torch for terabytes. Each check raises a
one-line ``PredictorError`` naming the field; ``label`` names the net ("Social-GRU").
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, fields, is_dataclass
from typing import Any, TypeVar

from predictors.errors import PredictorError, short_repr

T = TypeVar("T")


def wrong_type(label: str, name: str, kind: str, value: object) -> PredictorError:
    return PredictorError(
        f"{label} config holds a value of the wrong type: {name} must be {kind}, got {short_repr(value)}"
    )


def check_choice(label: str, name: str, value: object, choices: tuple[str, ...]) -> None:
    if not isinstance(value, str):
        raise wrong_type(label, name, "a string", value)
    if value not in choices:
        raise PredictorError(f"{label} {name} {short_repr(value)} is not one of {list(choices)}")


def check_int(label: str, name: str, value: object, low: int, high: int) -> None:
    # bool is an int to Python, but `"heads": true` in a JSON file is a mistake, not 1
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise wrong_type(label, name, "an integer", value)
    if not low <= int(value) <= high:
        raise PredictorError(f"{label} {name} must be in {low}..{high}, got {value}")


def check_positive_float(label: str, name: str, value: object, high: float) -> None:
    """A finite number in ``(0, high]``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise wrong_type(label, name, "a number", value)
    if not math.isfinite(float(value)):
        raise PredictorError(f"{label} {name} must be a finite number, got {value!r}")
    if not 0 < float(value) <= high:
        raise PredictorError(f"{label} {name} must be in (0, {high:g}], got {value}")


def check_parameter_count(label: str, count: int, limit: int, hint: str) -> None:
    if count > limit:
        raise PredictorError(
            f"this {label} net would have {count:,} parameters, more than the {limit:,} allowed ({hint})"
        )


def config_to_dict(config: Any) -> dict:
    if not is_dataclass(config) or isinstance(config, type):
        raise TypeError(f"expected a dataclass instance, got {type(config).__name__}")
    return asdict(config)


def config_from_dict(cls: type[T], values: object, label: str) -> T:
    """``cls(**values)``, refusing anything but a JSON object of ``cls``'s field names."""
    if not isinstance(values, dict):
        raise PredictorError(f"a {label} config must be a JSON object, got {short_repr(values)}")
    known = {f.name for f in fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(values) - known)
    if unknown:
        raise PredictorError(
            f"unknown {label} config keys {short_repr(unknown, 200)}; expected a subset of {sorted(known)}"
        )
    return cls(**values)  # __post_init__ checks every value's type and range
