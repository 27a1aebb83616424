"""Hostile and faulty data files: every one gives ``DatasetFormatError`` naming the file, the line and the
reason (``predictors.data.validate`` for ndjson, ``ewap.read_obsmat`` for obsmat), through every loader,
and the CLI prints it as one line with exit code 2 -- never a traceback, a numpy warning or silent acceptance.
Each bad file is generated here from a small valid one."""

from __future__ import annotations

import json
import os
import pathlib
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from predictors.data.datamodule import TrajnetDataModule
from predictors.data.ewap import read_obsmat
from predictors.data.prepare import prepare_ewap
from predictors.data.stats import file_stats
from predictors.data.trajnet_io import read_scenes, validate_ndjson
from predictors.data.validate import MAX_LINE_BYTES
from predictors.data.windows import load_file_arrays
from predictors.errors import DatasetFormatError, PredictorError
from predictors.evaluate import load_eval_scenes
from tests.cli_calls import run_cli
from tests.predictors.samples import (
    STEP,
    ewap_rows,
    scene,
    track,
    vouch_for,
    walk_scene_records,
    write_lines,
    write_obsmat,
    write_tiny_ewap,
    write_walk_file,
)

VALID = walk_scene_records()  # line 1: scene 0 (primary 1, frames 0-200); lines 2-46: tracks
N = len(VALID)
NEST = 100_000


def nan_track(frame: int, ped: int) -> str:
    return json.dumps(track(frame, ped, 0.0, 0.0)).replace('"x": 0.0', '"x": NaN')


# case -> (records of the file, line of the error, fragment of the reason)
BAD_NDJSON: dict[str, tuple[list, int, str]] = {
    "frame beyond int64": (
        VALID + [track(2**70, 1, 0.0, 0.0)],
        N + 1,
        "'f' is 1180591620717411303424, outside",
    ),
    "pedestrian beyond int64": (VALID + [track(0, 2**70, 0.0, 0.0)], N + 1, "'p' is 1180591620717411303424"),
    "scene id beyond int64": (VALID + [scene(2**64, 1, 0, 200)], N + 1, "scene 'id' is 18446744073709551616"),
    "frame 1e9 + 1": (VALID + [track(10**9 + 1, 1, 0.0, 0.0)], N + 1, "outside the supported range 0..1e+09"),
    "negative frame": (VALID + [track(-10, 1, 0.0, 0.0)], N + 1, "'f' is -10, outside"),
    "scene end beyond bound": (VALID + [scene(5, 1, 0, 10**12)], N + 1, "scene 'e' is 1000000000000"),
    "integer of 5000 digits": (
        VALID + ['{"track": {"f": ' + "9" * 5000 + "}}"],
        N + 1,
        "invalid JSON (Exceeds",
    ),
    "deep nesting": (VALID + ["[" * NEST + "]" * NEST], N + 1, "nested too deeply"),
    "deep nesting in a tag": (
        VALID[:1]
        + ['{"scene": {"id": 1, "p": 1, "s": 0, "e": 200, "tag": ' + "[" * NEST + "]" * NEST + "}}"],
        2,
        "nested too deeply",
    ),
    "tracks without scenes": (VALID[1:], 1, "track at frame 0, but the file has no scene record"),
    "primary never observed (NaN)": (
        VALID[:1] + [nan_track(0, 1)] + VALID[2:],
        2,
        "scene 0: primary pedestrian 1 has no position (NaN) at frame 0",
    ),
    "primary without rows": (VALID + [scene(3, 7, 0, 200)], N + 1, "primary pedestrian 7 has no track row"),
    "x = Infinity": (
        VALID + ['{"track": {"f": 0, "p": 2, "x": Infinity, "y": 0}}'],
        N + 1,
        "'x' is infinite",
    ),
    "y = -1e400 (overflows to -inf)": (
        VALID + ['{"track": {"f": 0, "p": 2, "x": 0, "y": -1e400}}'],
        N + 1,
        "'y' is infinite",
    ),
    "x = 1e300": (VALID + [track(0, 2, 1e300, 0.0)], N + 1, "'x' is 1e+300 m, outside the supported range"),
    # the bound is exclusive: |x| < 1e5 m
    "y = -1e5 exactly": (VALID + [track(0, 2, 0.0, -1e5)], N + 1, "'y' is -100000.0 m, outside"),
    "x = 10**400 (integer)": (
        VALID + ['{"track": {"f": 0, "p": 2, "x": 1' + "0" * 400 + ', "y": 0}}'],
        N + 1,
        "'x' is 1000",
    ),
    "x is a string": (VALID + [track(0, 2, "1.5", 0.0)], N + 1, "'x' must be a number, got '1.5'"),
    "y is null": (VALID + [track(0, 2, 1.0, None)], N + 1, "'y' must be a number, got None"),
    "frame is a float": (VALID + [track(10.0, 2, 1.0, 0.0)], N + 1, "'f' must be an integer, got 10.0"),
    "pedestrian is a bool": (VALID + [track(10, True, 1.0, 0.0)], N + 1, "'p' must be an integer, got True"),
    "fps is NaN": (
        VALID + ['{"scene": {"id": 9, "p": 1, "s": 0, "e": 200, "fps": NaN}}'],
        N + 1,
        "scene 'fps' must be a number",
    ),
    "fps is a huge integer": (
        VALID + ['{"scene": {"id": 9, "p": 1, "s": 0, "e": 200, "fps": 1' + "0" * 400 + "}}"],
        N + 1,
        "scene 'fps' must be a number",
    ),
    # a rate of 0 frames per second has no time step (DT = 1 / fps)
    "fps is 0": (
        VALID + ['{"scene": {"id": 9, "p": 1, "s": 0, "e": 200, "fps": 0}}'],
        N + 1,
        "scene 'fps' must be a number in (0, 1e+04], got 0",
    ),
    "track is null": (VALID + ['{"track": null}'], N + 1, '"track" must be a JSON object, got NoneType'),
    "null line": (VALID + ["null"], N + 1, 'exactly one of "scene" or "track"'),
    "scene and track in one record": (
        VALID + [{**scene(9, 1, 0, 200), **track(0, 1, 0.0, 0.0)}],
        N + 1,
        'exactly one of "scene" or "track"',
    ),
    # two tracks outside every scene: the first one is named
    "tracks after every scene": (
        VALID + [track(300, 1, 0.0, 0.0), track(400, 1, 0.0, 0.0)],
        N + 1,
        "track frame 300 lies outside every scene's [s, e] frame range",
    ),
    "UTF-8 byte-order mark": (
        ["\ufeff" + json.dumps(VALID[0])] + VALID[1:],
        1,
        "starts with a UTF-8 byte-order mark; save the file without one",
    ),
    # a line cut short (a writer killed mid-line), its end column named: it was "column 1", of the next line
    "a line cut short": (
        VALID + ['{"track": {"f": 0, "p": 2, "x": 1'],
        N + 1,
        "invalid JSON (Expecting ',' delimiter at column 34)",
    ),
    # json's own message ends "starting at", followed by its column: it read "starting at at column 20"
    "a line cut inside a name": (
        VALID + ['{"track": {"f": 0, "p'],
        N + 1,
        "invalid JSON (Unterminated string starting at column 20)",
    ),
    "carriage returns only": (["\r".join(json.dumps(r) for r in VALID)], 1, "invalid JSON (Extra data"),
    # line 2 is pedestrian 1 at frame 0, (0, 0): the reader kept one of the two and dropped the other
    "a second position for a pedestrian and frame": (
        VALID + [track(0, 1, 0.3, 0.0)],
        N + 1,
        "pedestrian 1 at frame 0 has another position on line 2 (0.0, 0.0 against 0.3, 0.0)",
    ),
    # the reader places a row by pedestrian and frame alone: rows differing only in a prediction file's
    # fields (prediction_number, scene_id) overwrote each other as silently
    "a second position for a pedestrian and frame under another scene_id": (
        VALID + [{"track": {"f": 0, "p": 1, "x": 0.3, "y": 0.0, "prediction_number": 1, "scene_id": 7}}],
        N + 1,
        "pedestrian 1 at frame 0 has another position on line 2 (0.0, 0.0 against 0.3, 0.0)",
    ),
    # the optional fields are null or ids; a list or an object ended validation in a TypeError (unhashable)
    "prediction_number is a list": (
        VALID + [{"track": {"f": 0, "p": 2, "x": 0.0, "y": 1.0, "prediction_number": [1]}}],
        N + 1,
        "track 'prediction_number' must be an integer, got [1]",
    ),
    "scene_id is an object": (
        VALID + [{"track": {"f": 0, "p": 2, "x": 0.0, "y": 1.0, "scene_id": {"a": 1}}}],
        N + 1,
        "track 'scene_id' must be an integer, got {'a': 1}",
    ),
    "scene_id beyond the id bound": (
        VALID + [{"track": {"f": 0, "p": 2, "x": 0.0, "y": 1.0, "scene_id": 10**12}}],
        N + 1,
        "track 'scene_id' is 1000000000000, outside the supported range",
    ),
    # NaN (not observed) against a position is a conflict too: which one the reader kept decided whether
    # the pedestrian was seen. Line 3 is pedestrian 2 at frame 0, (0, 1); y agrees, only x differs
    "NaN against a position for a pedestrian and frame": (
        VALID + ['{"track": {"f": 0, "p": 2, "x": NaN, "y": 1.0}}'],
        N + 1,
        "pedestrian 2 at frame 0 has another position on line 3 (0.0, 1.0 against nan, 1.0)",
    ),
}


def write_bad(path: Path, case: str) -> tuple[Path, int, str]:
    records, line, reason = BAD_NDJSON[case]
    return write_lines(path, records), line, reason


def assert_names_file_and_line(error: DatasetFormatError, path: Path, line: int | None, reason: str) -> None:
    assert error.path == str(path)
    assert error.line == line
    where = f"{path}:{line}: " if line is not None else f"{path}: "
    assert str(error).startswith(where), str(error)
    assert reason in error.reason
    assert "\n" not in str(error) and len(str(error)) < len(str(path)) + 300  # one short line


@pytest.mark.parametrize("case", sorted(BAD_NDJSON))
def test_malformed_ndjson_names_file_line_and_reason(case, tmp_path):
    path, line, reason = write_bad(tmp_path / "bad.ndjson", case)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy overflow or cast warnings on the way
        with pytest.raises(DatasetFormatError) as info:
            validate_ndjson(path)
    assert_names_file_and_line(info.value, path, line, reason)


LOADERS = {
    "read_scenes": read_scenes,
    "load_eval_scenes": load_eval_scenes,
    "load_file_arrays": load_file_arrays,
    "file_stats": file_stats,
    "TrajnetSceneDataset via the data module": lambda p: TrajnetDataModule([p], [p], []).setup("fit"),
}


@pytest.mark.parametrize("case", ["deep nesting", "frame beyond int64", "tracks without scenes", "x = 1e300"])
@pytest.mark.parametrize("loader", sorted(LOADERS))
def test_every_loader_goes_through_the_validation(loader, case, tmp_path):
    path, line, reason = write_bad(tmp_path / "bad.ndjson", case)
    with pytest.raises(DatasetFormatError) as info:
        LOADERS[loader](path)
    assert_names_file_and_line(info.value, path, line, reason)


@pytest.mark.parametrize("blank", ["", "   ", "\t", " \r"])
def test_blank_lines_are_skipped_by_every_reader(blank, tmp_path):
    plain = write_lines(tmp_path / "plain.ndjson", VALID)
    spaced = write_lines(tmp_path / "spaced.ndjson", VALID[:5] + [blank] + VALID[5:] + [blank])
    expected = read_scenes(plain, require_length=21)
    got = read_scenes(spaced, require_length=21)
    assert [(s.id, s.agents.tolist(), s.frames.tolist()) for s in got] == [
        (s.id, s.agents.tolist(), s.frames.tolist()) for s in expected
    ]
    np.testing.assert_array_equal(got[0].xy, expected[0].xy)
    assert len(load_eval_scenes(spaced)) == 1
    assert len(load_file_arrays(spaced, disk_cache=False)) == 1


def test_other_agents_may_still_be_nan(tmp_path):
    """TrajNet++'s own "not observed" stays accepted for agents other than the primary."""
    records = VALID[:5] + [nan_track(10, 2)] + VALID[6:]
    assert json.loads(json.dumps(VALID[5]))["track"]["p"] == 2
    scenes = read_scenes(write_lines(tmp_path / "nan.ndjson", records))
    assert np.isnan(scenes[0].xy[1, 1, 0])


def test_a_scene_spanning_a_billion_frames_reads_quickly(tmp_path):
    """trajnetplusplustools.Reader looks up every frame number in [s, e]; ours bisects over the rows."""
    records = [scene(0, 1, 0, 10**9)] + [track(k * STEP, 1, 0.5 * k, 0.0) for k in range(21)]
    started = time.perf_counter()
    scenes = read_scenes(write_lines(tmp_path / "long.ndjson", records), require_length=21)
    assert time.perf_counter() - started < 5
    assert scenes[0].frames.tolist() == list(range(0, 201, STEP))


def test_a_line_of_exactly_the_cap_passes(tmp_path):
    """MAX_LINE_BYTES bytes then the newline is within the cap; one byte more is not (test below)."""
    text = json.dumps(VALID[0])
    padded = text + " " * (MAX_LINE_BYTES - len(text))  # JSON allows trailing spaces
    assert len(padded.encode()) == MAX_LINE_BYTES
    path = write_lines(tmp_path / "padded.ndjson", [padded] + VALID[1:])
    assert validate_ndjson(path).n_tracks == N - 1


def test_a_track_covered_by_an_earlier_longer_scene_passes(tmp_path):
    """Scene 0 spans frames 0-200 and scene 1 only 20-40: frame 100 is in scene 0 although the scene that
    starts last before it (scene 1) ended at 40 -- coverage takes the furthest end so far, not the last."""
    records = VALID[:1] + [scene(1, 1, 20, 40)] + VALID[1:]
    path = write_lines(tmp_path / "nested.ndjson", records)
    assert validate_ndjson(path).scene_lines == {0: 1, 1: 2}


def test_a_primary_seen_only_at_the_scene_end_frame_is_present(tmp_path):
    """[s, e] includes e: pedestrian 3 has rows at frames 0, 10 and 20, so a scene 15-20 led by it has one
    (at 20)."""
    path = write_lines(tmp_path / "end.ndjson", VALID + [scene(1, 3, 15, 20)])
    assert sorted(validate_ndjson(path).scene_lines) == [0, 1]


def test_prediction_fields_are_null_or_ids_and_never_separate_positions(tmp_path):
    """prediction_number and scene_id may be absent, null or ids, and a row repeating a pedestrian's
    position at a frame under them passes. Several predictions of one pedestrian and frame are refused: the
    reader keeps one row per pedestrian and frame whatever those fields say (it used to pass validation and
    train on whichever row came last)."""
    same = [
        {"track": {"f": 0, "p": 1, "x": 0.0, "y": 0.0, "prediction_number": None, "scene_id": 0}},
        {"track": {"f": 0, "p": 1, "x": 0.0, "y": 0.0, "prediction_number": 2, "scene_id": 5}},
    ]
    path = write_lines(tmp_path / "repeats.ndjson", VALID + same)
    assert validate_ndjson(path).n_tracks == N - 1 + 2
    predictions = VALID + [
        {"track": {"f": 0, "p": 1, "x": 0.3, "y": 0.0, "prediction_number": 1, "scene_id": 0}},
        {"track": {"f": 0, "p": 1, "x": 0.4, "y": 0.0, "prediction_number": 2, "scene_id": 0}},
    ]
    path = write_lines(tmp_path / "predictions.ndjson", predictions)
    with pytest.raises(DatasetFormatError) as info:
        read_scenes(path)
    assert_names_file_and_line(info.value, path, N + 1, "pedestrian 1 at frame 0 has another position")


def test_a_line_longer_than_the_cap(tmp_path):
    path = write_lines(tmp_path / "long.ndjson", VALID + ['{"scene": "' + "x" * MAX_LINE_BYTES + '"}'])
    with pytest.raises(DatasetFormatError) as info:
        read_scenes(path)
    assert_names_file_and_line(info.value, path, N + 1, f"line longer than {MAX_LINE_BYTES} bytes")


def test_a_directory_or_a_fifo_is_no_data_file(tmp_path):
    directory = tmp_path / "dir.ndjson"
    directory.mkdir()
    fifo = tmp_path / "fifo.ndjson"
    os.mkfifo(fifo)  # opening it would block forever
    for path, reason in ((directory, "is a directory"), (fifo, "not a regular file")):
        for loader in (read_scenes, load_eval_scenes, load_file_arrays, read_obsmat):
            with pytest.raises(DatasetFormatError) as info:
                loader(path)
            assert_names_file_and_line(info.value, path, None, reason)
    with pytest.raises(DatasetFormatError, match="no such file"):
        read_scenes(tmp_path / "absent.ndjson")


@pytest.mark.parametrize("loader", [read_scenes, read_obsmat, load_file_arrays])
def test_an_unreadable_file(loader, tmp_path, monkeypatch):
    path = write_walk_file(tmp_path / "locked.ndjson")
    real_open = pathlib.Path.open

    def refusing_open(self, *args, **kwargs):
        if self == path:
            raise PermissionError(13, "Permission denied", str(self))
        return real_open(self, *args, **kwargs)

    monkeypatch.setattr(pathlib.Path, "open", refusing_open)  # chmod does not stop root
    with pytest.raises(DatasetFormatError) as info:
        loader(path)
    assert_names_file_and_line(info.value, path, None, "cannot read (Permission denied)")


def test_an_empty_training_file(tmp_path):
    empty = write_lines(tmp_path / "empty.ndjson", [])
    walk = write_walk_file(tmp_path / "walk.ndjson")
    assert read_scenes(empty) == []  # an empty split is a valid file ...
    with pytest.raises(DatasetFormatError) as info:  # ... but nothing to train on
        TrajnetDataModule([empty], [walk], []).setup("fit")
    assert_names_file_and_line(info.value, empty, None, "holds no scenes")
    with pytest.raises(DatasetFormatError) as info:  # nor to pick the best epoch by
        TrajnetDataModule([walk], [empty], []).setup("fit")
    assert_names_file_and_line(info.value, empty, None, "holds no scenes; validation needs one")
    with pytest.raises(PredictorError, match="the train files hold no scenes; training needs one: "):
        TrajnetDataModule([empty, empty], [walk], []).setup("fit")
    TrajnetDataModule([walk], [walk], [empty]).setup("test")  # an empty test split is only 0 scenes


# ---- raw BIWI EWAP obsmat.txt ----

GOOD_ROWS = ewap_rows(40, 10)


def obsmat_line(*values) -> bytes:
    return "".join(f"{v:>16}" if isinstance(v, str) else f"{v:16.7e}" for v in values).encode()


# case -> (extra line appended to a valid obsmat, fragment of the reason)
BAD_OBSMAT: dict[str, tuple[bytes, str]] = {
    "frame 1e30": (
        obsmat_line(1e30, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        "frame 1e+30 outside the supported range",
    ),
    "frame 0": (obsmat_line(0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), "frame 0 outside the supported range"),
    "id 1e30": (obsmat_line(5.0, 1e30, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), "id 1e+30 outside the supported range"),
    "negative id": (
        obsmat_line(5.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        "id -1 outside the supported range",
    ),
    "x 1e300": (obsmat_line(5.0, 1.0, 1e300, 0.0, 0.0, 0.0, 0.0, 0.0), "pos_x 1e+300 m outside"),
    "y -2e5": (obsmat_line(5.0, 1.0, 0.0, 0.0, -2e5, 0.0, 0.0, 0.0), "pos_y -200000 m outside"),
    "fractional frame": (obsmat_line(5.5, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), "must be integers"),
    "7 columns": (obsmat_line(5.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0), "expected 8 numeric columns, found 7"),
    "9 columns": (obsmat_line(*[5.0] * 9), "expected 8 numeric columns, found 9"),
    "NaN position": (obsmat_line(5.0, 1.0, "nan", 0.0, 0.0, 0.0, 0.0, 0.0), "pos_x not finite"),
    "NaN velocity": (obsmat_line(5.0, 1.0, 0.0, 0.0, 0.0, "NaN", 0.0, 0.0), "v_x not finite"),
    "infinite frame": (obsmat_line("inf", 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), "frame not finite"),
    "text": (b"this line is no annotation, just eight words", "non-numeric value 'this' in column frame"),
    "underscore in a number": (
        obsmat_line("1_1", 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        "non-numeric value '1_1'",
    ),
    "binary garbage": (b"\xff\xfe" + obsmat_line(*[5.0] * 7), "non-numeric value"),
}


@pytest.mark.parametrize("case", sorted(BAD_OBSMAT))
def test_malformed_obsmat_names_file_line_and_reason(case, tmp_path):
    extra, reason = BAD_OBSMAT[case]
    path = write_obsmat(tmp_path / "obsmat.txt", GOOD_ROWS)
    path.write_bytes(path.read_bytes() + extra + b"\r\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(DatasetFormatError) as info:
            read_obsmat(path)
    assert_names_file_and_line(info.value, path, len(GOOD_ROWS) + 1, reason)


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (b"", "no annotation rows"),
        (b"\r\n  \r\n", "no annotation rows"),
        (obsmat_line(*[1.0] * 8), "two distinct frames"),
    ],
)
def test_obsmat_without_a_sequence(content, reason, tmp_path):
    path = tmp_path / "obsmat.txt"
    path.write_bytes(content)
    with pytest.raises(DatasetFormatError) as info:
        read_obsmat(path)
    assert_names_file_and_line(info.value, path, None, reason)


# ---- the command line ----


@pytest.fixture
def prepared(tmp_path):
    out = tmp_path / "prepared"
    prepare_ewap(write_tiny_ewap(tmp_path / "data"), out, categorize_scenes=False, log=lambda msg: None)
    return out


def assert_cli_error(code: int, err: str, *expected: str) -> None:
    assert code == 2
    assert "Traceback" not in err and "Warning" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("crowdmpc "), err
    for fragment in expected:
        assert fragment in last, err


def test_cli_evaluate_accepts_a_blank_line(prepared, capsys):
    target = prepared / "test" / "biwi_eth.ndjson"
    lines = target.read_text().splitlines()
    target.write_text("\n".join(lines[:3] + [""] + lines[3:]) + "\n\n")
    vouch_for(prepared, "test/biwi_eth.ndjson")
    code, out, err = run_cli(
        capsys, "evaluate", "--predictor", "constant_velocity", "--data-dir", str(prepared)
    )
    assert code == 0, err
    assert "test/biwi_eth.ndjson" in out


@pytest.mark.parametrize("case", ["deep nesting", "primary never observed (NaN)", "frame beyond int64"])
def test_cli_evaluate_reports_a_hostile_file_in_one_line(case, prepared, capsys):
    target = prepared / "test" / "biwi_eth.ndjson"
    _, line, reason = write_bad(target, case)
    vouch_for(prepared, "test/biwi_eth.ndjson")
    code, _, err = run_cli(
        capsys, "evaluate", "--predictor", "constant_velocity", "--data-dir", str(prepared)
    )
    assert_cli_error(code, err, f"{target}:{line}: ", reason)
    assert len(err.strip().splitlines()) == 1


def test_cli_prepare_reports_a_huge_frame_without_warnings(tmp_path, capsys):
    raw = write_tiny_ewap(tmp_path / "data")
    obsmat = raw / "seq_eth" / "obsmat.txt"
    obsmat.write_bytes(obsmat.read_bytes() + obsmat_line(1e30, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) + b"\r\n")
    line = len(obsmat.read_bytes().splitlines())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code, _, err = run_cli(
            capsys, "data", "prepare", "--raw", str(raw), "--out", str(tmp_path / "o"), "--no-tags"
        )
    assert_cli_error(code, err, f"{obsmat}:{line}: frame 1e+30 outside the supported range")
    assert len(err.strip().splitlines()) == 1


def test_cli_stats_reports_tracks_without_scenes(tmp_path, capsys):
    path, line, reason = write_bad(tmp_path / "d" / "bad.ndjson", "tracks without scenes")
    code, _, err = run_cli(capsys, "data", "stats", str(tmp_path / "d"))
    assert_cli_error(code, err, f"{path}:{line}: ", reason)
    assert len(err.strip().splitlines()) == 1


def test_cli_train_on_an_empty_file(tmp_path, capsys):
    empty = write_lines(tmp_path / "empty.ndjson", [])
    walk = write_walk_file(tmp_path / "walk.ndjson")
    argv = ["train", "--model", "vanilla_lstm", "--train", str(empty), "--val", str(walk)]
    code, _, err = run_cli(capsys, *argv, "--epochs", "1", "--no-progress", "--out", str(tmp_path / "run"))
    # checked before Lightning starts: the one line is the whole output
    assert_cli_error(code, err, f"{empty}: holds no scenes")
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("split", ["--test", "--val"])
def test_cli_train_reads_the_evaluated_files_before_training(split, tmp_path, capsys):
    """A TrajNet++ test/ file (9 observed steps, no ground truth) passes the format check but not the
    evaluation, which ran after training: the run trained, then ended without metrics. Validation and test
    files are now read as the evaluation reads them before Lightning starts, and nothing is written."""
    observed = [r for r in VALID[1:] if r["track"]["f"] <= 8 * STEP]
    no_truth = write_lines(tmp_path / "test_private.ndjson", [scene(0, 1, 0, 8 * STEP), *observed])
    walk = str(write_walk_file(tmp_path / "walk.ndjson"))
    files = {"--train": walk, "--val": walk, "--test": walk, split: str(no_truth)}
    argv = ["train", "--model", "vanilla_lstm", *[a for kv in files.items() for a in kv]]
    out = tmp_path / "run"
    code, _, err = run_cli(capsys, *argv, "--epochs", "1", "--no-progress", "--out", str(out))
    assert_cli_error(code, err, f"{no_truth}:1: scene 0 has 9 steps, the evaluation needs 21")
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()


def steps_scene(steps: int) -> list[dict]:
    """One scene whose primary walks ``steps`` evenly spaced frames, a neighbour beside it."""
    tracks = [track(k * STEP, p, 0.5 * k, p - 1.0) for k in range(steps) for p in (1, 2)]
    return [scene(0, 1, 0, (steps - 1) * STEP), *tracks]


@pytest.mark.parametrize(
    ("split", "steps", "reason"),
    [
        ("--train", 19, "scene 0: primary pedestrian 1 has 19 frames, need 21"),
        ("--train", 25, "scene 0: primary pedestrian 1 has 25 frames, need 21"),
        ("--val", 19, "scene 0 has 19 steps, the evaluation needs 21"),
    ],
)
def test_cli_train_reads_the_training_files_as_the_data_module_before_training(
    split, steps, reason, tmp_path, capsys
):
    """The data module takes training scenes of exactly 21 steps, the pre-check did not (a training file
    only had to parse): such a file was refused after Lightning's banner and left a run folder of logs and
    settings. Every file is now loaded as the data module loads it, first; a validation scene needs 21
    steps or more, as the evaluation does."""
    odd = write_lines(tmp_path / "odd.ndjson", steps_scene(steps))
    walk = str(write_walk_file(tmp_path / "walk.ndjson"))
    files = {"--train": walk, "--val": walk, split: str(odd)}
    argv = ["train", "--model", "vanilla_lstm", *[a for kv in files.items() for a in kv]]
    out = tmp_path / "run"
    code, _, err = run_cli(capsys, *argv, "--epochs", "1", "--no-progress", "--out", str(out))
    assert_cli_error(code, err, f"{odd}:1: {reason}")
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_validation_reads_a_longer_scene_as_the_evaluation_does(tmp_path, capsys):
    """A --val scene of 25 steps was refused ("has 25 frames, need 21") where --test and evaluate score its
    last 21: the epoch picked was not chosen on what the evaluation reads. Each epoch's validation now reads
    the same last 21 steps, and such a file trains."""
    long = write_lines(tmp_path / "long.ndjson", steps_scene(25))
    [scene_21] = load_eval_scenes(long)
    walk = str(write_walk_file(tmp_path / "walk.ndjson"))
    module = TrajnetDataModule([walk], [long], [long], batch_size=1)
    module.setup("fit")
    arrays = module.datasets["val"].arrays[0]
    np.testing.assert_array_equal(arrays.xy, scene_21.xy.astype(np.float32))
    assert arrays.xy.shape[0] == 21 and np.isnan(arrays.xy).sum() == 0
    with pytest.raises(DatasetFormatError, match="has 25 frames, need 21"):
        load_file_arrays(long)  # training's windows stay whole scenes
    out = tmp_path / "run"
    argv = ["train", "--model", "vanilla_lstm", "--train", walk, "--val", str(long), "--epochs", "1"]
    code, _, err = run_cli(capsys, *argv, "--no-progress", "--out", str(out))
    assert code == 0, err
    metrics = json.loads(next(out.glob("*.metrics.json")).read_text())
    assert metrics["metrics"]["val"]["scenes"] == 1


def test_a_scenes_tag_reaches_the_reader(tmp_path):
    """The tag (TrajNet++ type and sub-types) is what `data stats` counts by type."""
    records = [scene(0, 1, 0, 200, tag=[3, [2, 4]])] + VALID[1:]
    [read] = read_scenes(write_lines(tmp_path / "tagged.ndjson", records))
    assert read.tag == [3, [2, 4]]


def test_a_repeated_identical_row_passes(tmp_path):
    """Only a conflicting repeat is refused: the same row twice says nothing new."""
    path = write_lines(tmp_path / "twice.ndjson", VALID + [VALID[1]])
    assert validate_ndjson(path).n_tracks == N
