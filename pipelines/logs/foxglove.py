"""Foxglove's SceneUpdate JSON schema, built from its published parts (same field names, types and titles).

It follows Foxglove's published schema (github.com/foxglove/foxglove-sdk, formerly foxglove/schemas,
``schemas/jsonschema/SceneUpdate.json``) field for field, so that Foxglove's 3D panel recognises the
``/scene`` channel by name. Like the published one since October 2025 ("JSONSchema: mark all properties
required", foxglove-sdk #682), every object requires all its properties (times and durations excepted, as
there), so the checker (``crowdmpc review --check``) refuses an entity without, say, its ``frame_id``.

Why no ``foxglove-sdk``: it writes Protobuf through its own MCAP writer (a 19 MB compiled wheel) while every
channel here is JSON for one reader and one checker; the schema below is about a hundred lines of dicts.
"""

from __future__ import annotations

from typing import Any, Final


def _object(title: str, properties: dict[str, Any], description: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {
        "title": title,
        "type": "object",
        "properties": properties,
        "required": list(properties),
    }
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
# The schema itself; pipelines.logs.schemas.SCENE_UPDATE names it for the /scene channel.
SCENE_UPDATE: Final = {
    **_object(
        "foxglove.SceneUpdate",
        {
            "deletions": _array(_SCENE_ENTITY_DELETION, "Scene entities to delete"),
            "entities": _array(SCENE_ENTITY, "Scene entities to add or replace"),
        },
        "An update to the entities displayed in a 3D scene",
    ),
    "$comment": "Foxglove's published schema (github.com/foxglove/foxglove-sdk)",
}
