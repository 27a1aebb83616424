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
import types
import typing
from collections.abc import Mapping
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
    """``cls(**values)``, refusing anything but a JSON object of ``cls``'s field names (named in str's order:
    a dict built in Python may hold keys of other types beside them)."""
    if not isinstance(values, dict):
        raise PredictorError(f"a {label} config must be a JSON object, got {short_repr(values)}")
    known = {f.name for f in fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(values) - known, key=str)
    if unknown:
        raise PredictorError(
            f"unknown {label} config keys {short_repr(unknown, 200)}; expected a subset of {sorted(known)}"
        )
    return cls(**values)  # __post_init__ checks every value's type and range


# What each plain annotation takes from a JSON file, and how a message names it. An int is a number to
# float (JSON writes 2 for 2.0); a bool is no int here, though Python's isinstance says it is.
_PLAIN_TYPES: dict[object, tuple[str, Any]] = {
    int: ("an integer", lambda v: isinstance(v, int) and not isinstance(v, bool)),
    float: ("a number", lambda v: isinstance(v, int | float) and not isinstance(v, bool)),
    bool: ("true or false", lambda v: isinstance(v, bool)),
    str: ("a string", lambda v: isinstance(v, str)),
    type(None): ("null", lambda v: v is None),
}


def check_annotated_types(cls: type, values: Mapping[str, Any], label: str) -> None:
    """PredictorError naming the first of ``values`` that its dataclass field's annotation refuses.

    A plugin's config class may check nothing in ``__post_init__``: a string size then failed deep in torch
    ("empty(): argument 'size' ... must be tuple of ints"), naming no key, and ``true`` built a net of width
    1. Only plain annotations (int, float, bool, str, None and unions of them) are checked; a field of any
    other type, or a class whose annotations do not resolve, is left to the class."""
    try:
        hints = typing.get_type_hints(cls)
    except Exception:  # a name only its own module's TYPE_CHECKING block imports: nothing to check against
        return
    for name, value in values.items():
        members = _plain_members(hints.get(name))
        if members is None:
            continue
        if not any(_PLAIN_TYPES[m][1](value) for m in members):
            kinds = " or ".join(_PLAIN_TYPES[m][0] for m in members)
            raise wrong_type(
                label, name, f"{kinds} ({cls.__name__}.{name}: {_annotation_text(cls, name)})", value
            )


def _plain_members(annotation: object) -> tuple[object, ...] | None:
    """``annotation``'s types when each is one of ``_PLAIN_TYPES`` (a union's members), else None."""
    if isinstance(annotation, type) and annotation in _PLAIN_TYPES:  # an annotation may be unhashable
        return (annotation,)
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        members = typing.get_args(annotation)
        return members if all(m in _PLAIN_TYPES for m in members) else None
    return None


def _annotation_text(cls: type, name: str) -> str:
    """The annotation as its class writes it ("int | None"), for a message."""
    written = next(f.type for f in fields(cls) if f.name == name)  # type: ignore[arg-type]
    return written if isinstance(written, str) else getattr(written, "__name__", repr(written))
