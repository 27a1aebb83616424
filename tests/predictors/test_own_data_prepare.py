"""Own raw data through `data prepare` and the ndjson reader: a 10 Hz obsmat refused (it was labelled
2.5 fps), steps no walker makes noted, splits without scenes noted or refused, a byte-order mark named."""

from __future__ import annotations

import numpy as np
import pytest

from predictors.data.ewap import read_obsmat
from predictors.data.ewap_checks import step_seconds
from predictors.data.prepare import prepare_ewap
from predictors.data.validate import parse_ndjson
from predictors.errors import DatasetFormatError, PredictorError
from tests.predictors.samples import ewap_rows, write_obsmat, write_tiny_ewap, write_walk_file


def _raw(tmp_path, eth: np.ndarray, hotel: np.ndarray | None = None):
    raw = tmp_path / "raw_ewap"
    write_obsmat(raw / "seq_eth" / "obsmat.txt", eth)
    hotel = ewap_rows(300, 10, pairs_every=9) if hotel is None else hotel
    write_obsmat(raw / "seq_hotel" / "obsmat.txt", hotel)
    return raw


def _prepare(raw, out, notes: list[str]) -> dict:
    return prepare_ewap(raw, out, categorize_scenes=False, log=lambda msg: None, note=notes.append)


def test_a_file_whose_velocities_imply_10_hz_is_refused_naming_it(tmp_path):
    rows = ewap_rows(300, 1)  # 0.48 m a row; velocities of 4.8 m/s make that 0.1 s a step
    rows[:, 5:8] *= 4
    raw = _raw(tmp_path, rows)
    with pytest.raises(DatasetFormatError) as caught:
        _prepare(raw, tmp_path / "out", [])
    message = str(caught.value)
    assert message.startswith(f"{raw / 'seq_eth' / 'obsmat.txt'}: ") and "\n" not in message
    assert "imply 0.100 s per annotated step" in message and "resample the file to 2.5 fps" in message
    assert not (tmp_path / "out").exists()


def test_the_time_step_is_read_from_positions_and_velocities_robustly(tmp_path):
    rows = ewap_rows(300, 6)
    with_v = read_obsmat(write_obsmat(tmp_path / "obsmat.txt", rows), velocities=True)
    seconds, tracks = step_seconds(with_v, 6)
    assert seconds == pytest.approx(0.4, abs=1e-3) and tracks == len(np.unique(rows[:, 1]))
    rows[:, 5:8] = 0.0  # no velocities: nothing to tell the time by, so nothing is refused
    assert step_seconds(read_obsmat(write_obsmat(tmp_path / "z.txt", rows), velocities=True), 6) is None
    _prepare(_raw(tmp_path, rows), tmp_path / "out", [])


def test_a_step_no_walker_makes_is_noted_once_per_file_with_an_example(tmp_path):
    rows = ewap_rows(300, 6)
    ped = rows[:, 1] == 3
    later = ped & (rows[:, 0] > np.sort(rows[ped, 0])[10])
    rows[later, 2] += 8.0  # pedestrian 3 leaps 8 m in one 0.4 s step: its id taken by someone else
    notes: list[str] = []
    _prepare(_raw(tmp_path, rows), tmp_path / "out", notes)
    (note,) = [n for n in notes if "faster than" in n]
    obsmat = tmp_path / "raw_ewap" / "seq_eth" / "obsmat.txt"
    assert note.startswith(f"note: {obsmat}: 1 step of a pedestrian")
    assert "pedestrian 3, frames" in note and "\n" not in note


def test_plausible_tracks_give_no_note(tmp_path):
    notes: list[str] = []
    _prepare(write_tiny_ewap(tmp_path), tmp_path / "out", notes)
    assert not [n for n in notes if "faster than" in n]


def test_no_scene_in_any_split_is_refused_and_an_empty_split_noted(tmp_path):
    short = ewap_rows(30, 6)  # one pair of 23 steps: too few frames in each part of the split
    with pytest.raises(PredictorError, match="no scene in any split"):
        _prepare(_raw(tmp_path, short, ewap_rows(30, 10)), tmp_path / "out", [])
    assert not (tmp_path / "out").exists()
    notes: list[str] = []
    manifest = _prepare(_raw(tmp_path, ewap_rows(300, 6), ewap_rows(30, 10)), tmp_path / "out", notes)
    empty = [name for name, entry in manifest["files"].items() if not entry["scenes"]]
    assert empty and sorted(notes) == sorted(
        f"note: {tmp_path / 'out' / name} holds no scenes (too few frames of its sequence in that split, "
        "or no pedestrian there whom TrajNet++'s scene rules keep)"
        for name in empty
    )


def test_a_byte_order_mark_is_named_in_ndjson_and_obsmat(tmp_path):
    walk = write_walk_file(tmp_path / "walk.ndjson")
    walk.write_bytes(b"\xef\xbb\xbf" + walk.read_bytes())
    with pytest.raises(DatasetFormatError, match=r"walk.ndjson:1: starts with a UTF-8 byte-order mark"):
        parse_ndjson(walk)
    obsmat = write_obsmat(tmp_path / "obsmat.txt", ewap_rows(100, 6))
    obsmat.write_bytes(b"\xef\xbb\xbf" + obsmat.read_bytes())
    with pytest.raises(DatasetFormatError, match="save the file without one"):
        read_obsmat(obsmat)
