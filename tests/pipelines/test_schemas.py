"""The JSON-schema checker on hand-made cases, and the schemas themselves."""

from __future__ import annotations

import pytest

from pipelines.errors import PipelineError
from pipelines.logs.jsonschema import unsupported_keywords, validate
from pipelines.logs.schemas import CHANNELS, SCENE_UPDATE

POINT = {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2}
RECORD = {
    "type": "object",
    "properties": {
        "step": {"type": "integer", "minimum": 0},
        "where": POINT,
        "fallback": {"type": ["string", "null"], "enum": [None, "brake"]},
    },
    "required": ["step", "where"],
    "additionalProperties": False,
}


def test_a_valid_message_has_no_errors():
    assert validate({"step": 3, "where": [1.0, -2], "fallback": None}, RECORD) == []
    assert validate({"step": 3.0, "where": [1.0, -2]}, RECORD) == []  # 3.0 is an integer in JSON


@pytest.mark.parametrize(
    ("message", "error"),
    [
        ({"where": [0, 0]}, "$: missing required property 'step'"),
        ({"step": True, "where": [0, 0]}, "$.step: expected integer, got bool"),
        ({"step": -1, "where": [0, 0]}, "$.step: -1 is below the minimum 0"),
        ({"step": 1, "where": [0]}, "$.where: 1 items, expected at least 2"),
        ({"step": 1, "where": [0, "x"]}, "$.where[1]: expected number, got str"),
        ({"step": 1, "where": [0, 0], "other": 1}, "$: unexpected property 'other'"),
        ({"step": 1, "where": [0, 0], "fallback": "shifted"}, "$.fallback: 'shifted' is not one of"),
        ([1, 2], "$: expected object, got list"),
    ],
)
def test_each_violation_is_reported_with_its_path(message, error):
    errors = validate(message, RECORD)
    assert len(errors) == 1 and errors[0].startswith(error), errors


def test_one_of_constants_and_unsupported_keywords():
    line = SCENE_UPDATE.schema["properties"]["entities"]["items"]["properties"]["lines"]["items"]
    line_type = {"type": "object", "properties": {"type": line["properties"]["type"]}}
    assert validate({"type": 0}, line_type) == []
    assert "matches 0 of the 3 options" in validate({"type": 5}, line_type)[0]
    # JSON's true is not 1 (Python's True == 1 let a boolean pass as LINE_LOOP), nor 0 false
    assert "matches 0 of the 3 options" in validate({"type": True}, line_type)[0]
    assert validate(0, {"enum": [False]}) and validate(False, {"const": 0})
    assert validate([1], {"const": [True]})
    assert validate(1.0, {"const": 1}) == validate([False], {"enum": [[False]]}) == []
    with pytest.raises(PipelineError, match=r"keyword\(s\) \['pattern'\]"):
        validate("a", {"type": "string", "pattern": "a+"})


def test_every_channel_schema_uses_only_checked_keywords():
    assert unsupported_keywords({"properties": {"a": {"items": {"pattern": "x"}}}}) == ["$.a[]: pattern"]
    for schema in CHANNELS.values():
        assert unsupported_keywords(schema.schema) == [], schema.name


def test_scene_update_follows_foxglove_field_names():
    entity = SCENE_UPDATE.schema["properties"]["entities"]["items"]
    assert list(entity["properties"]) == [
        "timestamp",
        "frame_id",
        "id",
        "lifetime",
        "frame_locked",
        "metadata",
        "arrows",
        "cubes",
        "spheres",
        "cylinders",
        "lines",
        "triangles",
        "texts",
        "models",
    ]
    sphere = entity["properties"]["spheres"]["items"]
    assert sphere["title"] == "foxglove.SpherePrimitive" and list(sphere["properties"]) == [
        "pose",
        "size",
        "color",
    ]


def test_scene_update_requires_every_property_as_foxglove_does_and_the_recorder_writes_them():
    """Foxglove's schema marks every property of every object required (foxglove-sdk #682, October 2025;
    times and durations excepted): an entity without its frame_id is an error, and what the recorder writes
    for /scene passes."""
    from pipelines.logs.jsonschema import validate

    def objects(node):
        if isinstance(node, dict):
            if node.get("type") == "object" and node.get("title") not in ("time", "duration"):
                yield node
            for value in node.values():
                yield from objects(value)

    found = list(objects(SCENE_UPDATE.schema))
    assert len(found) > 20 and all(o["required"] == list(o["properties"]) for o in found)
    entity = SCENE_UPDATE.schema["properties"]["entities"]["items"]
    message = {
        "deletions": [],
        "entities": [{name: [] for name, p in entity["properties"].items() if p.get("type") == "array"}],
    }
    message["entities"][0].update(
        timestamp={"sec": 1, "nsec": 0}, id="robot0", lifetime={"sec": 0, "nsec": 0}, frame_locked=False
    )
    assert validate(message, SCENE_UPDATE.schema) == ["$.entities[0]: missing required property 'frame_id'"]
    message["entities"][0]["frame_id"] = "world"
    assert validate(message, SCENE_UPDATE.schema) == []
