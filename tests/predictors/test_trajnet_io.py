import json
import math

import numpy as np
import pytest

from predictors.data.trajnet_io import read_scenes, validate_ndjson
from predictors.errors import DatasetFormatError
from tests.predictors.samples import STEP, scene, track, walk_scene_records, write_lines, write_walk_file


def test_reads_scenes_with_primary_first_and_nan_for_missing(tmp_path):
    scenes = read_scenes(write_walk_file(tmp_path / "walk.ndjson"), require_length=21)
    assert [s.id for s in scenes] == [0, 1]
    first, second = scenes
    assert first.primary == 1 and first.agents.tolist() == [1, 2, 3]
    assert first.xy.shape == (21, 3, 2)
    assert first.frames.tolist() == list(range(0, 201, STEP))
    np.testing.assert_allclose(first.xy[4, 0], [2.0, 0.0])  # 0.5 m per step along x
    np.testing.assert_allclose(first.xy[4, 1], [2.0, 1.0])
    assert np.isnan(first.xy[3:, 2]).all() and not np.isnan(first.xy[:3, 2]).any()  # ped 3: three steps
    assert second.agents.tolist()[0] == 2
    assert first.line == 1 and second.line == 2


def test_summary_counts_tracks_pedestrians_frames(tmp_path):
    summary = validate_ndjson(write_walk_file(tmp_path / "walk.ndjson"))
    assert summary.n_tracks == 21 * 2 + 3
    assert summary.pedestrians == {1, 2, 3}
    assert len(summary.frames) == 21
    assert summary.scene_lines == {0: 1, 1: 2}


def test_empty_file_is_an_empty_dataset(tmp_path):
    path = tmp_path / "empty.ndjson"
    path.write_text("")
    assert read_scenes(path) == []


def test_nan_coordinate_is_missing_not_zero(tmp_path):
    records = walk_scene_records()
    # JSON has no NaN literal, but Python's json (and TrajNet++'s reader) accept one
    records[5] = '{"track": {"f": 10, "p": 2, "x": NaN, "y": 1.0}}'  # step 1 of ped 2
    scenes = read_scenes(write_lines(tmp_path / "nan.ndjson", records))
    assert np.isnan(scenes[0].xy[1, 1, 0]) and not np.isnan(scenes[0].xy[2, 1, 0])


def test_require_length_rejects_short_primary(tmp_path):
    records = [
        r
        for r in walk_scene_records()
        if not ("track" in r and r["track"]["p"] == 1 and r["track"]["f"] == 200)
    ]
    path = write_lines(tmp_path / "short.ndjson", records)
    with pytest.raises(
        DatasetFormatError, match=r"short.ndjson:1: scene 0: primary pedestrian 1 has 20 frames"
    ):
        read_scenes(path, require_length=21)


def _bad(records, tmp_path):
    return write_lines(tmp_path / "bad.ndjson", records)


MALFORMED = {
    "bad json": (
        lambda r: r[:3] + ['{"track": {"f": 10, "p": 1, "x": 0.5, "y": 0.0'] + r[3:],
        4,
        "invalid JSON",
    ),
    "missing key": (
        lambda r: r[:2] + [{"track": {"f": 0, "p": 9, "x": 1.0}}] + r[2:],
        3,
        r"lacks key\(s\) \['y'\]",
    ),
    "non-numeric x": (
        lambda r: r[:2] + [track(0, 9, "1.0", 2.0)] + r[2:],
        3,
        "'x' must be a number, got '1.0'",
    ),
    "string frame": (lambda r: r[:2] + [track("0", 9, 1.0, 2.0)] + r[2:], 3, "'f' must be an integer"),
    "bool frame": (lambda r: r[:2] + [track(True, 9, 1.0, 2.0)] + r[2:], 3, "'f' must be an integer"),
    "infinite y": (
        lambda r: r[:2] + ['{"track": {"f": 0, "p": 9, "x": 1.0, "y": Infinity}}'] + r[2:],
        3,
        "infinite",
    ),
    "frame outside scenes": (
        lambda r: r + [track(500, 1, 0.0, 0.0)],
        47,
        "frame 500 lies outside every scene",
    ),
    "neither scene nor track": (lambda r: r + [{"person": {}}], 47, 'exactly one of "scene" or "track"'),
    "not an object": (lambda r: r + ["[1, 2]"], 47, 'exactly one of "scene" or "track"'),
    "duplicate scene id": (lambda r: r + [scene(0, 2, 0, 200)], 47, "scene id 0 repeats the one on line 1"),
    "scene ends first": (lambda r: r + [scene(7, 2, 200, 0)], 47, "starts at frame 200 after its end 0"),
    "primary absent": (lambda r: r + [scene(8, 42, 0, 200)], 47, "primary pedestrian 42 has no track row"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_files_name_file_line_and_reason(case, tmp_path):
    edit, line, reason = MALFORMED[case]
    path = _bad(edit(walk_scene_records()), tmp_path)
    with pytest.raises(DatasetFormatError, match=reason) as info:
        validate_ndjson(path)
    assert info.value.line == line
    assert info.value.path == str(path)
    assert str(info.value).startswith(f"{path}:{line}: ")


def test_track_outside_scenes_is_found_between_two_scenes(tmp_path):
    records = [
        scene(0, 1, 0, 20),
        scene(1, 1, 100, 120),
        track(0, 1, 0, 0),
        track(100, 1, 0, 0),
        track(50, 1, 0, 0),
    ]
    with pytest.raises(DatasetFormatError, match="frame 50 lies outside") as info:
        validate_ndjson(write_lines(tmp_path / "gap.ndjson", records))
    assert info.value.line == 5


def test_missing_file_and_non_utf8(tmp_path):
    with pytest.raises(DatasetFormatError, match="no such file"):
        validate_ndjson(tmp_path / "absent.ndjson")
    path = tmp_path / "binary.ndjson"
    path.write_bytes(json.dumps(scene(0, 1, 0, 0)).encode() + b"\n\xff\xfe\n")
    with pytest.raises(DatasetFormatError, match="not UTF-8") as info:
        validate_ndjson(path)
    assert info.value.line == 2


def test_official_hotel_file_reads(shared_data):
    scenes = read_scenes(shared_data / "trajnetpp_vita/train/real_data/biwi_hotel.ndjson", require_length=21)
    assert len(scenes) == 229
    assert all(s.xy.shape[0] == 21 and not np.isnan(s.xy[:, 0]).any() for s in scenes)
    assert math.isclose(
        np.mean([s.xy.shape[1] for s in scenes]), 13.8, abs_tol=0.05
    )  # shared README's figure
