"""JSON schemas of the recorded channels, and a checker for the subset of JSON Schema they use.

Every channel is JSON-encoded with a JSON schema (MCAP's ``jsonschema`` encoding). The ``crowdmpc.*`` schemas
are ours and strict (``required``, no extra properties). ``foxglove.SceneUpdate`` follows Foxglove's published
schema (github.com/foxglove/schemas, ``schemas/jsonschema/SceneUpdate.json``) field for field, so that
Foxglove's 3D panel recognises the channel by name; like the published one it lists no required fields.

Why no ``foxglove-sdk``: it writes Protobuf through its own MCAP writer (a 19 MB compiled wheel) while every
channel here is JSON for one reader and one checker; the schema below is about a hundred lines of dicts.
Why no ``jsonschema``: it is not a project dependency, and the keywords used here take ~60 lines to check.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any, Final

from pipelines.errors import PipelineError

SCHEMA_ENCODING: Final[str] = "jsonschema"  # MCAP's well-known schema encoding for JSON schemas
MESSAGE_ENCODING: Final[str] = "json"


@dataclass(frozen=True, eq=False)
class MessageSchema:
    """A named JSON schema, serialised once: the recorder compares and writes ``data``, never the dict."""

    name: str  # e.g. "crowdmpc.Robots", "foxglove.SceneUpdate"
    schema: dict[str, Any]
    data: bytes = field(init=False, repr=False)

    def __post_init__(self):
        if not self.name:
            raise PipelineError("a message schema needs a non-empty name")
        object.__setattr__(self, "data", json.dumps(self.schema, sort_keys=True).encode())

    def same_as(self, other: MessageSchema) -> bool:
        return self is other or (self.name == other.name and self.data == other.data)


# ------------------------------------------------------------------------------------------------------------
# crowdmpc channels. Points are [x, y] in metres in the "world" frame; times are s since the episode start.
# ------------------------------------------------------------------------------------------------------------

_NUMBER: Final = {"type": "number"}
_POINT2: Final = {"type": "array", "items": _NUMBER, "minItems": 2, "maxItems": 2}
_POINTS: Final = {"type": "array", "items": _POINT2}  # (K, 2)
_TRACKS: Final = {"type": "array", "items": _POINTS}  # (A, H, 2) or (H, N, 2)


def _record(title: str, properties: dict[str, Any], optional: tuple[str, ...] = ()) -> dict[str, Any]:
    """A strict object schema: every property required except ``optional``, nothing else allowed."""
    return {
        "title": title,
        "type": "object",
        "properties": properties,
        "required": [name for name in properties if name not in optional],
        "additionalProperties": False,
    }


_STAMP: Final = {
    "time": {"type": "number", "minimum": 0, "description": "s since episode start"},
    "step": {"type": "integer", "minimum": 0},
}

ROBOTS = MessageSchema(
    "crowdmpc.Robots",
    _record(
        "crowdmpc.Robots",
        {
            **_STAMP,
            "positions": {**_POINTS, "description": "(M, 2) m"},
            "velocities": {**_POINTS, "description": "(M, 2) m/s"},
            "goals": {**_POINTS, "description": "(M, 2) m"},
            "actions": {
                "type": ["array", "null"],
                "items": _POINT2,
                "description": "(M, 2) m/s^2 applied (clipped) from this state on; null at the end",
            },
            "commanded": {
                "type": ["array", "null"],
                "items": _POINT2,
                "description": "(M, 2) m/s^2 the controller's command, before clipping; null at the end",
            },
            "reached": {"type": "array", "items": {"type": "boolean"}},
        },
    ),
)

HUMANS = MessageSchema(
    "crowdmpc.Humans",
    _record(
        "crowdmpc.Humans",
        {
            **_STAMP,
            "positions": {**_POINTS, "description": "(N, 2) m"},
            "velocities": {**_POINTS, "description": "(N, 2) m/s"},
            "goals": {**_POINTS, "description": "(N, 2) m"},
        },
    ),
)

PLAN = MessageSchema(
    "crowdmpc.Plan",
    _record(
        "crowdmpc.Plan",
        {
            **_STAMP,
            "positions": {**_TRACKS, "description": "(M, H, 2) m, each robot's plan at t+1..t+H (to 1e-6 m)"},
        },
    ),
)

PREDICTION = MessageSchema(
    "crowdmpc.Prediction",
    _record(
        "crowdmpc.Prediction",
        {
            **_STAMP,
            "positions": {**_TRACKS, "description": "(H, N_h, 2) m, used by the final solve (to 1e-6 m)"},
            "iterations": {
                "type": "array",
                "items": _TRACKS,
                "description": "(H, N_h, 2) per IBR iteration; empty unless iterations are recorded",
            },
        },
    ),
)

SOLVER = MessageSchema(
    "crowdmpc.Solver",
    _record(
        "crowdmpc.Solver",
        {
            **_STAMP,
            "status": {"type": "string"},
            "solve_time_s": {"type": "number", "minimum": 0},
            "iterations": {"type": "integer", "minimum": 0},
            "potential": {"type": ["number", "null"], "description": "F_t, Eq. (16)"},
            "fallback": {"type": ["string", "null"], "enum": [None, "shifted", "brake"]},
            "extra": {"type": "object"},
        },
    ),
)

_SCALAR: Final = {"type": ["number", "boolean", "string", "null"]}
_SOLVE_STATS: Final = _record(
    "crowdmpc.SolveStats",
    {name: {"type": ["number", "null"]} for name in ("median_ms", "p95_ms", "max_ms", "mean_iterations")},
)

EPISODE_METRICS = MessageSchema(
    "crowdmpc.EpisodeMetrics",
    _record(
        "crowdmpc.EpisodeMetrics",
        {
            "seed": {"type": "integer"},
            "scenario": {"type": "string"},
            "controller": {"type": "string"},
            "predictor": {"type": ["string", "null"]},
            "n_humans": {"type": "integer", "minimum": 0},
            "n_robots": {"type": "integer", "minimum": 1},
            "n_steps": {"type": "integer", "minimum": 0},
            "metrics": {
                "type": "object",
                "description": "crowdsim.metrics.EpisodeMetrics fields; NaN written as null",
                "additionalProperties": {"type": ["number", "boolean", "string", "null", "array"]},
            },
            "solve": _SOLVE_STATS,
            "statuses": {"type": "object", "additionalProperties": {"type": "integer", "minimum": 0}},
            "fallbacks": {"type": "object", "additionalProperties": {"type": "integer", "minimum": 0}},
        },
    ),
)

# ------------------------------------------------------------------------------------------------------------
# Foxglove's SceneUpdate, built from its published parts (same field names, types and titles).
# ------------------------------------------------------------------------------------------------------------


def _object(title: str, properties: dict[str, Any], description: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {"title": title, "type": "object", "properties": properties}
    if description:
        out["description"] = description
    return out


def _numbers(*names: str) -> dict[str, Any]:
    return {name: {"type": "number"} for name in names}


def _array(items: dict[str, Any], description: str) -> dict[str, Any]:
    return {"type": "array", "items": items, "description": description}


_TIME: Final = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
}
_DURATION: Final = {
    "type": "object",
    "title": "duration",
    "properties": {
        "sec": {"type": "integer"},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
}
_VECTOR3: Final = _object("foxglove.Vector3", _numbers("x", "y", "z"))
_POINT3: Final = _object("foxglove.Point3", _numbers("x", "y", "z"))
_QUATERNION: Final = _object("foxglove.Quaternion", _numbers("x", "y", "z", "w"))
_POSE: Final = _object("foxglove.Pose", {"position": _VECTOR3, "orientation": _QUATERNION})
_COLOR: Final = _object("foxglove.Color", _numbers("r", "g", "b", "a"), "RGBA, each between 0 and 1")
_KEY_VALUE: Final = _object("foxglove.KeyValuePair", {"key": {"type": "string"}, "value": {"type": "string"}})


def _enum(title: str, *options: str) -> dict[str, Any]:
    return {"title": title, "oneOf": [{"title": name, "const": i} for i, name in enumerate(options)]}


SPHERE_PRIMITIVE: Final = _object(
    "foxglove.SpherePrimitive", {"pose": _POSE, "size": _VECTOR3, "color": _COLOR}, "A sphere or ellipsoid"
)
LINE_PRIMITIVE: Final = _object(
    "foxglove.LinePrimitive",
    {
        "type": _enum("foxglove.LineType", "LINE_STRIP", "LINE_LOOP", "LINE_LIST"),
        "pose": _POSE,
        "thickness": {"type": "number"},
        "scale_invariant": {"type": "boolean"},
        "points": {"type": "array", "items": _POINT3},
        "color": _COLOR,
        "colors": {"type": "array", "items": _COLOR},
        "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}},
    },
    "A series of points connected by lines",
)
_ARROW_PRIMITIVE: Final = _object(
    "foxglove.ArrowPrimitive",
    {
        "pose": _POSE,
        **_numbers("shaft_length", "shaft_diameter", "head_length", "head_diameter"),
        "color": _COLOR,
    },
)
_CUBE_PRIMITIVE: Final = _object("foxglove.CubePrimitive", {"pose": _POSE, "size": _VECTOR3, "color": _COLOR})
_CYLINDER_PRIMITIVE: Final = _object(
    "foxglove.CylinderPrimitive",
    {"pose": _POSE, "size": _VECTOR3, **_numbers("bottom_scale", "top_scale"), "color": _COLOR},
)
_TRIANGLE_LIST_PRIMITIVE: Final = _object(
    "foxglove.TriangleListPrimitive",
    {
        "pose": _POSE,
        "points": {"type": "array", "items": _POINT3},
        "color": _COLOR,
        "colors": {"type": "array", "items": _COLOR},
        "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}},
    },
)
_TEXT_PRIMITIVE: Final = _object(
    "foxglove.TextPrimitive",
    {
        "pose": _POSE,
        "billboard": {"type": "boolean"},
        "font_size": {"type": "number"},
        "scale_invariant": {"type": "boolean"},
        "color": _COLOR,
        "text": {"type": "string"},
    },
)
_MODEL_PRIMITIVE: Final = _object(
    "foxglove.ModelPrimitive",
    {
        "pose": _POSE,
        "scale": _VECTOR3,
        "color": _COLOR,
        "override_color": {"type": "boolean"},
        "url": {"type": "string"},
        "media_type": {"type": "string"},
        "data": {"type": "string", "contentEncoding": "base64"},
    },
)
SCENE_ENTITY: Final = _object(
    "foxglove.SceneEntity",
    {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "id": {"type": "string"},
        "lifetime": _DURATION,
        "frame_locked": {"type": "boolean"},
        "metadata": {"type": "array", "items": _KEY_VALUE},
        "arrows": _array(_ARROW_PRIMITIVE, "Arrow primitives"),
        "cubes": _array(_CUBE_PRIMITIVE, "Cube primitives"),
        "spheres": _array(SPHERE_PRIMITIVE, "Sphere primitives"),
        "cylinders": _array(_CYLINDER_PRIMITIVE, "Cylinder primitives"),
        "lines": _array(LINE_PRIMITIVE, "Line primitives"),
        "triangles": _array(_TRIANGLE_LIST_PRIMITIVE, "Triangle list primitives"),
        "texts": _array(_TEXT_PRIMITIVE, "Text primitives"),
        "models": _array(_MODEL_PRIMITIVE, "Model primitives"),
    },
    "A visual element in a 3D scene, made of primitives sharing one frame of reference",
)
_SCENE_ENTITY_DELETION: Final = _object(
    "foxglove.SceneEntityDeletion",
    {
        "timestamp": _TIME,
        "type": _enum("foxglove.SceneEntityDeletionType", "MATCHING_ID", "ALL"),
        "id": {"type": "string"},
    },
)
SCENE_UPDATE = MessageSchema(
    "foxglove.SceneUpdate",
    {
        **_object(
            "foxglove.SceneUpdate",
            {
                "deletions": _array(_SCENE_ENTITY_DELETION, "Scene entities to delete"),
                "entities": _array(SCENE_ENTITY, "Scene entities to add or replace"),
            },
            "An update to the entities displayed in a 3D scene",
        ),
        "$comment": "Foxglove's published schema (github.com/foxglove/schemas)",
    },
)

# Topic -> schema of every channel an episode recording holds.
CHANNELS: Final[dict[str, MessageSchema]] = {
    "/robots": ROBOTS,
    "/humans": HUMANS,
    "/mpc/plan": PLAN,
    "/mpc/prediction": PREDICTION,
    "/mpc/solver": SOLVER,
    "/scene": SCENE_UPDATE,
    "/episode/metrics": EPISODE_METRICS,
}

# ------------------------------------------------------------------------------------------------------------
# Checking a decoded message against a schema (the keywords above, nothing more).
# ------------------------------------------------------------------------------------------------------------

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
    if "const" in schema and value != schema["const"]:
        errors.append(f"{path}: expected {schema['const']!r}, got {value!r}")
    if "enum" in schema and value not in schema["enum"]:
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
