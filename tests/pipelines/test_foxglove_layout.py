"""docs/foxglove_layout.json, the Foxglove layout for a recorded run: every panel it places is configured,
and every topic and message path it names is one a recording holds, with the schema's field of a number to
plot. A renamed topic or field would leave the panel empty in Foxglove without a word."""

import json
from pathlib import Path

import pytest

from pipelines.logs.scene import FRAME_ID
from pipelines.logs.schemas import CHANNELS

LAYOUT = Path(__file__).resolve().parents[2] / "docs" / "foxglove_layout.json"
PANEL_TYPES = {"3D", "Plot", "RawMessages"}  # Foxglove's panel type is the id before "!"


@pytest.fixture(scope="module")
def layout() -> dict:
    return json.loads(LAYOUT.read_text(encoding="utf-8"))


def leaves(node) -> list[str]:
    """The panel ids of a layout tree (a panel id, or a split with "first" and "second")."""
    if isinstance(node, str):
        return [node]
    assert set(node) <= {"direction", "first", "second", "splitPercentage"} and node["direction"] in (
        "row",
        "column",
    )
    return leaves(node["first"]) + leaves(node["second"])


def field_schema(topic: str, field: str) -> dict:
    """The JSON schema of ``field`` as the recording stores its topic's schema (the bytes it writes)."""
    return json.loads(CHANNELS[topic].data)["properties"][field]


def test_every_placed_panel_is_configured_and_of_a_known_type(layout):
    placed = leaves(layout["layout"])
    assert sorted(placed) == sorted(layout["configById"]) and len(set(placed)) == len(placed)
    assert {panel.split("!")[0] for panel in placed} == PANEL_TYPES


def test_the_3d_panel_shows_the_scene_in_its_frame(layout):
    (three_d,) = [c for panel, c in layout["configById"].items() if panel.startswith("3D!")]
    assert three_d["followTf"] == FRAME_ID and three_d["followMode"] == "follow-none"
    assert set(three_d["topics"]) == {"/scene"} and three_d["topics"]["/scene"]["visible"]
    assert CHANNELS["/scene"].name == "foxglove.SceneUpdate"


def test_every_plotted_path_is_a_numeric_field_of_a_recorded_topic(layout):
    plots = [c for panel, c in layout["configById"].items() if panel.startswith("Plot!")]
    paths = [p["value"] for plot in plots for p in plot["paths"]]
    assert paths
    for path in paths:
        topic, _, field = path.partition(".")
        assert topic in CHANNELS, path
        kinds = field_schema(topic, field)["type"]
        assert {"number", "integer"} & set([kinds] if isinstance(kinds, str) else kinds), path


def test_the_raw_messages_panel_reads_a_recorded_topic(layout):
    (raw,) = [c for panel, c in layout["configById"].items() if panel.startswith("RawMessages!")]
    assert raw["topicPath"] in CHANNELS
