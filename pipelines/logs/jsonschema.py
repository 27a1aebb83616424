"""A checker for the subset of JSON Schema that the recorded channels' schemas use.

Why no ``jsonschema``: it is not a project dependency, and the keywords used here take ~60 lines to check.
A keyword outside the subset is an error rather than ignored, so that no part of a schema goes unchecked.
"""

from __future__ import annotations

import json
import math
from typing import Any, Final

from pipelines.errors import PipelineError

_ANNOTATIONS: Final = frozenset({"title", "description", "$comment", "$schema", "default", "examples"})
_CHECKED: Final = frozenset(
    {
        "type",
        "properties",
        "required",
        "additionalProperties",
        "items",
        "minItems",
        "maxItems",
        "minimum",
        "maximum",
        "enum",
        "const",
        "oneOf",
        "contentEncoding",
    }
)


def _is_type(value: Any, name: str) -> bool:
    if name == "object":
        return isinstance(value, dict)
    if name == "array":
        return isinstance(value, list)
    if name == "string":
        return isinstance(value, str)
    if name == "boolean":
        return isinstance(value, bool)
    if name == "null":
        return value is None
    if isinstance(value, bool):  # bool is an int in Python, never a number in JSON
        return False
    if name == "integer":
        return isinstance(value, int) or (isinstance(value, float) and value.is_integer())
    if name == "number":
        return isinstance(value, int | float) and math.isfinite(value)
    raise PipelineError(f"unsupported JSON schema type {name!r}")


def _json_equal(a: Any, b: Any) -> bool:
    """Equality as JSON Schema means it: Python's ``True == 1`` and ``False == 0`` hold, JSON's do not."""
    if isinstance(a, bool) or isinstance(b, bool):
        return isinstance(a, bool) and isinstance(b, bool) and a == b
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_json_equal(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_json_equal(a[k], b[k]) for k in a)
    return a == b


def validate(value: Any, schema: dict[str, Any], path: str = "$") -> list[str]:
    """Every violation of ``schema`` by ``value``, each as ``"<json path>: <reason>"``; empty when valid.

    Raises PipelineError on a keyword this checker does not implement, so no part of a schema goes unchecked.
    """
    unknown = set(schema) - _CHECKED - _ANNOTATIONS
    if unknown:
        raise PipelineError(
            f"JSON schema keyword(s) {sorted(unknown)} at {path} are not supported by the checker"
        )
    errors: list[str] = []
    if "type" in schema:
        types = schema["type"] if isinstance(schema["type"], list) else [schema["type"]]
        if not any(_is_type(value, t) for t in types):
            return [f"{path}: expected {' or '.join(types)}, got {_describe(value)}"]
    if "const" in schema and not _json_equal(value, schema["const"]):
        errors.append(f"{path}: expected {schema['const']!r}, got {value!r}")
    if "enum" in schema and not any(_json_equal(value, option) for option in schema["enum"]):
        errors.append(f"{path}: {value!r} is not one of {schema['enum']!r}")
    if "oneOf" in schema:
        matches = sum(not validate(value, option, path) for option in schema["oneOf"])
        if matches != 1:
            errors.append(
                f"{path}: {value!r} matches {matches} of the {len(schema['oneOf'])} options, not one"
            )
    if isinstance(value, int | float) and not isinstance(value, bool):
        if "minimum" in schema and value < schema["minimum"]:
            errors.append(f"{path}: {value} is below the minimum {schema['minimum']}")
        if "maximum" in schema and value > schema["maximum"]:
            errors.append(f"{path}: {value} is above the maximum {schema['maximum']}")
    if isinstance(value, list):
        if "minItems" in schema and len(value) < schema["minItems"]:
            errors.append(f"{path}: {len(value)} items, expected at least {schema['minItems']}")
        if "maxItems" in schema and len(value) > schema["maxItems"]:
            errors.append(f"{path}: {len(value)} items, expected at most {schema['maxItems']}")
        if "items" in schema:
            for i, item in enumerate(value):
                errors.extend(validate(item, schema["items"], f"{path}[{i}]"))
    if isinstance(value, dict):
        properties = schema.get("properties", {})
        for name in schema.get("required", ()):
            if name not in value:
                errors.append(f"{path}: missing required property {name!r}")
        extra = schema.get("additionalProperties", True)
        for name, item in value.items():
            if name in properties:
                errors.extend(validate(item, properties[name], f"{path}.{name}"))
            elif extra is False:
                errors.append(f"{path}: unexpected property {name!r}")
            elif isinstance(extra, dict):
                errors.extend(validate(item, extra, f"{path}.{name}"))
    return errors


def unsupported_keywords(schema: dict[str, Any], path: str = "$") -> list[str]:
    """Every keyword anywhere in ``schema`` that ``validate`` does not implement, as ``"<path>: <key>"``."""
    found = [f"{path}: {k}" for k in sorted(set(schema) - _CHECKED - _ANNOTATIONS)]
    for name, sub in schema.get("properties", {}).items():
        found += unsupported_keywords(sub, f"{path}.{name}")
    if isinstance(schema.get("items"), dict):
        found += unsupported_keywords(schema["items"], f"{path}[]")
    if isinstance(schema.get("additionalProperties"), dict):
        found += unsupported_keywords(schema["additionalProperties"], f"{path}.*")
    for i, option in enumerate(schema.get("oneOf", ())):
        found += unsupported_keywords(option, f"{path}|{i}")
    return found


def _describe(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, float) or math.isfinite(value) else repr(value)
    return f"{type(value).__name__} {text[:40]}"
