import json
from pathlib import Path

import numpy as np
import pytest

from predictors.data.ewap import infer_frame_step, read_obsmat, split_frames
from predictors.data.prepare import prepare_ewap
from predictors.data.selfcheck import Reference, compare_with_reference
from predictors.data.trajnet_io import read_scenes
from predictors.data.trajnet_scenes import SceneSpec, build_scenes, write_ndjson
from predictors.errors import DatasetFormatError, PredictorError
from predictors.hashing import sha256_file
from tests.predictors.samples import write_tiny_ewap


def walkers(n_steps=25, peds=(1, 2), step=0.5, spacing=1.0, frame_step=10):
    """Pedestrians walking +x side by side (``spacing`` m apart in y), one row per frame."""
    rows = [
        (k * frame_step, ped, step * k, spacing * i) for k in range(n_steps) for i, ped in enumerate(peds)
    ]
    return np.asarray(rows, dtype=float)


def keys(scenes):
    return [(s.primary, s.start_frame, s.end_frame) for s in scenes]


def test_chunks_of_21_rows_every_2_steps_per_pedestrian():
    scenes = build_scenes(walkers(), frame_step=10, categorize_scenes=False)
    # 25 rows -> windows starting at rows 0, 2, 4 (frames 0, 20, 40), for each pedestrian in order
    assert keys(scenes) == [(1, 0, 200), (1, 20, 220), (1, 40, 240), (2, 0, 200), (2, 20, 220), (2, 40, 240)]
    assert [s.id for s in scenes] == list(range(6))
    assert all(s.tag == 0 and s.fps == 2.5 for s in scenes)


def test_scene_ids_start_where_asked_and_pedestrians_keep_first_appearance_order():
    tracks = walkers(peds=(7, 3))
    scenes = build_scenes(tracks, frame_step=10, start_scene_id=100, categorize_scenes=False)
    assert [s.primary for s in scenes] == [7, 7, 7, 3, 3, 3]
    assert scenes[0].id == 100


def test_window_with_a_gap_in_the_primary_is_dropped():
    tracks = walkers(peds=(1, 2, 3))
    tracks = tracks[~((tracks[:, 0] == 100) & (tracks[:, 1] == 3))]  # pedestrian 3 unseen at frame 100
    # pedestrian 3: 24 rows, every 21-row window spans the 20-frame gap; 1 and 2 keep all three windows
    assert [p for p, _, _ in keys(build_scenes(tracks, frame_step=10, categorize_scenes=False))] == [
        1
    ] * 3 + [2] * 3


def _with_steps(steps):
    """walkers() over 21 rows (one window) with the given frame increments between its rows."""
    tracks = walkers(n_steps=21)
    frames = np.concatenate([[0], np.cumsum(steps)])
    tracks[:, 0] = frames[(tracks[:, 0] // 10).astype(int)]
    return tracks


def test_a_window_is_continuous_by_the_upper_median_step():
    # 20 increments, ten of 10 frames and ten of 14: the converter's median is the upper one (sorted
    # index 20 // 2 = 10), 14. So the window is a scene at frame_step 14 (max 14 < 1.5 x 14) and none at
    # frame_step 10, although the lower median 10 would pass (14 < 1.5 x 10)
    tracks = _with_steps([10] * 10 + [14] * 10)
    assert build_scenes(tracks, frame_step=10, categorize_scenes=False) == []
    assert keys(build_scenes(tracks, frame_step=14, categorize_scenes=False)) == [(1, 0, 240), (2, 0, 240)]


def test_a_step_of_exactly_one_and_a_half_times_the_median_is_a_gap():
    # scene.py continuous_frames keeps a window only if median x 1.5 > max: 10 x 1.5 = 15 is not > 15
    assert build_scenes(_with_steps([10] * 19 + [15]), frame_step=10, categorize_scenes=False) == []
    assert len(build_scenes(_with_steps([10] * 19 + [14]), frame_step=10, categorize_scenes=False)) == 2


def test_too_little_activity_drops_the_window():
    tracks = walkers()
    tracks = tracks[~((tracks[:, 0] == 100) & (tracks[:, 1] == 2))]
    # every window of pedestrian 1 contains frame 100: 2 x 21 - 1 = 41 rows < 42
    assert build_scenes(tracks, frame_step=10, categorize_scenes=False) == []


def test_pedestrians_in_different_10m_cells_are_not_close():
    assert build_scenes(walkers(spacing=10.0), frame_step=10, categorize_scenes=False) == []
    assert len(build_scenes(walkers(spacing=3.0), frame_step=10, categorize_scenes=False)) == 6
    # cells are floor(y / 10): y = 4 and 6 share cell 0 (rounding would part them, 0 and 1), y = 9 and 11
    # are in cells 0 and 1 (rounding would join them in cell 1)
    for low, close in ((4.0, True), (9.0, False)):
        tracks = walkers(spacing=2.0)
        tracks[:, 3] += low
        assert len(build_scenes(tracks, frame_step=10, categorize_scenes=False)) == (6 if close else 0)


def test_a_perfectly_still_primary_is_dropped_but_a_slow_one_is_kept():
    still = walkers(peds=(1,))
    still[:, 2] = 4.0
    slow = walkers(peds=(2,), step=0.01)
    scenes = build_scenes(np.concatenate([still, slow]), frame_step=10, categorize_scenes=False)
    assert [s.primary for s in scenes] == [2, 2, 2]


def test_frame_step_other_than_the_data_drops_everything():
    assert build_scenes(walkers(frame_step=6), frame_step=10, categorize_scenes=False) == []
    assert len(build_scenes(walkers(frame_step=6), frame_step=6, categorize_scenes=False)) == 6


def test_categorisation_tags_and_acceptance():
    walking = walkers(peds=(1, 2))
    slow = walkers(peds=(3,), step=0.02)  # moves 0.4 m in 21 steps: static (type I)
    slow[:, 3] = 0.5
    tracks = np.concatenate([walking, slow])
    # the legacy global generator (which pykalman samples from) must be left as it was
    before = np.random.get_state()[1].copy()  # noqa: NPY002
    scenes = build_scenes(tracks, frame_step=10, acceptance=(1.0, 1.0, 1.0, 1.0))
    after = np.random.get_state()[1]  # noqa: NPY002
    np.testing.assert_array_equal(after, before)
    tags = {(s.primary, s.start_frame): s.tag for s in scenes}
    assert tags[(1, 0)][0] in (2, 3)  # straight walk beside a neighbour: linear, or interacting (group)
    assert tags[(3, 0)] == (1, ())
    dropped = build_scenes(tracks, frame_step=10, acceptance=(0.0, 1.0, 1.0, 1.0))
    assert 3 not in {s.primary for s in dropped} and len(dropped) == 6
    assert build_scenes(tracks, frame_step=10) == build_scenes(tracks, frame_step=10)  # deterministic


def test_acceptance_draws_per_seed_primary_and_start():
    """Each scene draws from its own generator of (seed, primary, start frame): pedestrians 1 and 2 walk
    side by side over the same frames, yet at acceptance 1/2 they keep different windows, and another seed
    keeps others."""
    tracks = walkers(n_steps=41)  # 11 windows each

    def kept(seed):
        scenes = build_scenes(tracks, frame_step=10, acceptance=(0.5,) * 4, seed=seed)
        return [{s.start_frame for s in scenes if s.primary == p} for p in (1, 2)]

    first, second = kept(42)
    assert first != second and 0 < len(first) < 11
    assert kept(43) != [first, second]


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"chunk_stride": 0}, "chunk_stride >= 1"),
        ({"acceptance": (1.5, 1.0, 1.0, 1.0)}, "acceptance must be four probabilities"),
    ],
)
def test_build_scenes_refuses_bad_options(options, message):
    with pytest.raises(ValueError, match=message):
        build_scenes(walkers(), frame_step=10, **options)


def test_a_fractional_pedestrian_id_is_refused():
    tracks = walkers()
    tracks[4, 1] = 1.5  # would be truncated into pedestrian 1
    with pytest.raises(ValueError, match=r"tracks\[4\] has frame 20.0, pedestrian 1.5"):
        build_scenes(tracks, frame_step=10, categorize_scenes=False)


def test_write_ndjson_writes_the_rate_it_is_given(tmp_path):
    path = tmp_path / "x.ndjson"
    write_ndjson(path, [SceneSpec(0, 1, 0, 200, fps=5.0)], walkers(), fps=5.0)
    assert json.loads(path.read_text().splitlines()[0])["scene"]["fps"] == 5.0


def test_categorisation_reads_centimetres_and_static_means_under_one_metre():
    # the converter categorises the written file, coordinates rounded to cm: the primary's first window
    # goes from x = 0.004 (written 0.00) to 0.004 + 20 x 0.0498 = 1.000 (written 1.00). Its displacement is
    # 0.996 m as given but 1.00 m as written, and type I (static) needs < 1 m: so the scene is not static
    tracks = walkers(step=0.0498)
    tracks[:, 2] += 0.004
    scenes = build_scenes(tracks, frame_step=10, acceptance=None)
    tags = {(s.primary, s.start_frame): s.tag for s in scenes}
    assert tags[(1, 0)][0] != 1


def test_write_ndjson_rounds_to_centimetres_and_keeps_rows_at_primary_frames(tmp_path):
    tracks = walkers()
    tracks[0, 2] = 0.123456
    extra = np.asarray([[5.0, 9, 1.0, 1.0], [400.0, 9, 1.0, 1.0]])  # off the step grid / after every scene
    tracks = np.concatenate([tracks, extra])
    scenes = [SceneSpec(0, 1, 0, 200, 2.5, (2, ())), SceneSpec(1, 2, 40, 240)]
    path = tmp_path / "out.ndjson"
    write_ndjson(path, scenes, tracks)
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert lines[0] == {"scene": {"id": 0, "p": 1, "s": 0, "e": 200, "fps": 2.5, "tag": [2, []]}}
    assert lines[1]["scene"]["tag"] == 0
    frames = [line["track"]["f"] for line in lines[2:]]
    assert frames == sorted(frames) and set(frames) == set(range(0, 241, 10))
    assert lines[2]["track"] == {"f": 0, "p": 1, "x": 0.12, "y": 0.0}
    read = read_scenes(path, require_length=21)
    assert [s.primary for s in read] == [1, 2]


def test_write_ndjson_refuses_a_scene_built_at_another_rate(tmp_path):
    with pytest.raises(ValueError, match="scene 0 was built at 2.5 fps but is written as 5.0 fps"):
        write_ndjson(tmp_path / "x.ndjson", [SceneSpec(0, 1, 0, 200)], walkers(), fps=5.0)
    assert not (tmp_path / "x.ndjson").exists()


def test_write_ndjson_refuses_a_scene_without_its_primary(tmp_path):
    with pytest.raises(ValueError, match="primary 5 has no row"):
        write_ndjson(tmp_path / "x.ndjson", [SceneSpec(0, 5, 0, 200)], walkers())


def _spoilt(kind):
    """walkers() (row 2k + i: frame 10k, pedestrian i + 1 at (0.5k, i)) with bad rows from row 5 on."""
    tracks = walkers()
    if kind == "non-finite":
        tracks[7, 2] = np.nan  # frame 30, pedestrian 2
        tracks[9, 3] = np.inf
    elif kind == "fractional":
        tracks[5, 0] = 20.5  # frame 20, pedestrian 2
    elif kind == "one duplicate":
        tracks[10, 0] = 10  # frame 50, pedestrian 1 -> frame 10, as row 2
    else:
        tracks[6, 1] = 2  # frame 30, pedestrian 1 -> 2, as row 7
        tracks[10, 0] = 10  # frame 50, pedestrian 1 -> frame 10, as row 2
    return tracks


@pytest.mark.parametrize(
    ("kind", "message"),
    [
        (
            "non-finite",
            "tracks must be finite: tracks[7] = [30.0, 2.0, nan, 1.0] [frame, ped_id, x, y] "
            "(2 of 50 rows hold NaN or inf)",
        ),
        (
            "fractional",
            "frame and pedestrian ids in tracks must be integers: tracks[5] has frame 20.5, pedestrian 2.0 "
            "(1 of 50 rows)",
        ),
        (
            "duplicate",
            "tracks hold 2 duplicate (frame, pedestrian) rows; the first is tracks[7]: frame 30, "
            "pedestrian 2, already at tracks[6]",
        ),
        (  # one: "1 duplicate (frame, pedestrian) rows" before
            "one duplicate",
            "tracks hold 1 duplicate (frame, pedestrian) row; the first is tracks[10]: frame 10, "
            "pedestrian 1, already at tracks[2]",
        ),
    ],
)
def test_bad_tracks_are_refused_naming_the_first_bad_row(tmp_path, kind, message):
    tracks = _spoilt(kind)
    with pytest.raises(ValueError) as built:
        build_scenes(tracks, frame_step=10, categorize_scenes=False)
    assert str(built.value) == message
    with pytest.raises(ValueError) as written:
        write_ndjson(tmp_path / "x.ndjson", [SceneSpec(0, 1, 0, 200)], tracks)
    assert str(written.value) == message
    assert not (tmp_path / "x.ndjson").exists()


def test_split_frames_is_temporal_70_10_20():
    parts = split_frames(np.arange(0, 100, 10))
    assert parts["train"].tolist() == [0, 10, 20, 30, 40, 50, 60]
    assert parts["val"].tolist() == [70]
    assert parts["test"].tolist() == [80, 90]


def test_split_frames_truncates_as_trajnet_does():
    # TrajNet++'s convert.write cuts at int(n * fraction), a floor: 18 frames give int(12.6) = 12 train,
    # then int(1.8) = 1 val and the 5 left test (rounding would give 13 train)
    parts = split_frames(np.arange(18))
    assert [len(parts[k]) for k in ("train", "val", "test")] == [12, 1, 5]
    assert parts["val"].tolist() == [12]
    with pytest.raises(PredictorError, match="sum to <= 1, got train=0.8, val=0.3"):
        split_frames(np.arange(18), (0.8, 0.3))


def test_infer_frame_step():
    assert infer_frame_step(np.array([0, 6, 12, 18, 30, 36])) == 6
    # the most common step, not the smallest: one odd gap of 5 among steps of 10
    assert infer_frame_step(np.array([0, 10, 20, 30, 35, 45, 55])) == 10


def test_read_obsmat_picks_columns_and_shifts_frames(tmp_path):
    path = tmp_path / "obsmat.txt"
    path.write_bytes(b"  1.0 3.0 1.5 0.0 -2.5 0.1 0.0 0.2\r\n 11.0 3.0 1.6 0.0 -2.4 0.1 0.0 0.2\r\n")
    np.testing.assert_array_equal(read_obsmat(path), [[0, 3, 1.5, -2.5], [10, 3, 1.6, -2.4]])
    path.write_bytes(b"1 0 1 0 2 0 0 0\n11 0 1 0 2 0 0 0\n")  # ids run from 0 (the bounds are 0..1e9)
    assert read_obsmat(path)[:, 1].tolist() == [0, 0]


@pytest.mark.parametrize(
    ("content", "line", "reason"),
    [
        (b"1 2 3 4 5 6 7\n", 1, "expected 8 numeric columns, found 7"),
        (b"1 2 3 4 5 6 7 8\n1 2 x 4 5 6 7 8\n", 2, "non-numeric"),
        (b"1.5 2 3 4 5 6 7 8\n", 1, "must be integers"),
        (b"1 2 3 4 5 6 7 8\n11 2.5 3 4 5 6 7 8\n", 2, "frame 11 and id 2.5 must be integers"),
        # two pedestrians, but both at one frame: no time step to infer
        (b"1 2 3 4 5 6 7 8\n1 3 3 4 5 6 7 8\n", None, "annotations at a single frame"),
        (b"1 2 3 4 5 6 7 8\n\n1 2 3 4 5 6 7 8\n", 3, "repeats line 1"),
        (b"1 2 nan 4 5 6 7 8\n", 1, "finite"),
    ],
)
def test_read_obsmat_rejects_malformed_lines(tmp_path, content, line, reason):
    path = tmp_path / "obsmat.txt"
    path.write_bytes(content)
    with pytest.raises(DatasetFormatError, match=reason) as info:
        read_obsmat(path)
    assert info.value.line == line


def test_prepare_ewap_writes_splits_without_crossing_boundaries(tmp_path):
    raw = write_tiny_ewap(tmp_path)
    out = tmp_path / "prepared"
    manifest = prepare_ewap(raw, out, categorize_scenes=False, log=lambda msg: None)
    for name, seq in (("biwi_eth", "seq_eth"), ("biwi_hotel", "seq_hotel")):
        parts = split_frames(read_obsmat(raw / seq / "obsmat.txt")[:, 0])
        for split in ("train", "val", "test"):
            info = manifest["files"][f"{split}/{name}.ndjson"]
            scenes = read_scenes(out / split / f"{name}.ndjson", require_length=21)
            assert info["scenes"] == len(scenes) > 0
            low, high = parts[split][0], parts[split][-1]
            assert all(low <= s.start and s.end <= high for s in scenes)
        ids = [
            s.id for split in ("train", "val", "test") for s in read_scenes(out / split / f"{name}.ndjson")
        ]
        assert ids == list(range(len(ids)))  # ids run on across the splits of a sequence
    again = prepare_ewap(raw, tmp_path / "again", categorize_scenes=False, log=lambda msg: None)
    assert {k: v["sha256"] for k, v in again["files"].items()} == {
        k: v["sha256"] for k, v in manifest["files"].items()
    }


def test_prepare_ewap_manifest_records_what_was_done(tmp_path):
    """The manifest is how a prepared folder says how it was made: the fractions asked for (and used), each
    sequence's frame step, each file's first and last frame and its sha256."""
    raw = write_tiny_ewap(tmp_path)
    out = tmp_path / "prepared"
    manifest = prepare_ewap(
        raw, out, categorize_scenes=False, seed=7, fractions=(0.5, 0.25), log=lambda m: None
    )
    parameters = manifest["parameters"]
    assert parameters["split_fractions"] == {"train": 0.5, "val": 0.25, "test": 0.25}
    # untagged scenes are never dropped: no acceptance applies, whatever the default
    assert (parameters["seed"], parameters["categorized"], parameters["acceptance"]) == (7, False, None)
    # write_tiny_ewap's sequences step by 6 (eth) and 10 (hotel) frames
    assert {k: v["frame_step"] for k, v in manifest["sources"].items()} == {"biwi_eth": 6, "biwi_hotel": 10}
    for name, seq in (("biwi_eth", "seq_eth"), ("biwi_hotel", "seq_hotel")):
        frames = np.unique(read_obsmat(raw / seq / "obsmat.txt")[:, 0])
        n = len(frames)
        # split_frames' floor arithmetic by hand: [0, n/2), [n/2, n/2 + n/4), the rest
        bounds = {"train": (0, n // 2), "val": (n // 2, n // 2 + n // 4), "test": (n // 2 + n // 4, n)}
        for split, (lo, hi) in bounds.items():
            info = manifest["files"][f"{split}/{name}.ndjson"]
            assert info["frames"] == [int(frames[lo]), int(frames[hi - 1])]
            assert info["sha256"] == sha256_file(out / split / f"{name}.ndjson")
            assert all(
                frames[lo] <= s.start and s.end <= frames[hi - 1]
                for s in read_scenes(out / split / f"{name}.ndjson")
            )
    assert json.loads((out / "manifest.json").read_text()) == manifest


def test_hotel_reproduces_every_official_scene(shared_data, tmp_path):
    tracks = read_obsmat(shared_data / "raw_ewap/seq_hotel/obsmat.txt")
    official = shared_data / "trajnetpp_vita/train/real_data/biwi_hotel.ndjson"
    check = compare_with_reference(
        tracks, Reference(official, "official TrajNet++", compare_tags=False), frame_step=10, workdir=tmp_path
    )
    assert (check.reproduced, check.reference_scenes) == (229, 229)
    assert check.ours_moving_not_in_reference == 0  # the rest are static scenes TrajNet++ dropped at random


def test_scene_rows_and_windows_match_a_row_by_row_reference_on_shuffled_tracks():
    """Each scene's rows and each pedestrian's windows are found by binary search over rows sorted once
    (scanning every row per scene made `data synth` quadratic: 49 s at 1000 episodes); the brute-force
    scan is the reference, on rows in random order."""
    from predictors.data.trajnet_scenes import scene_track_rows

    rng = np.random.default_rng(3)
    tracks = np.concatenate(
        [walkers(n_steps=40, peds=(4, 9, 2)), walkers(n_steps=30, peds=(7,), spacing=3.0)]
    )
    tracks = tracks[rng.permutation(len(tracks))]
    scenes = build_scenes(tracks, frame_step=10, categorize_scenes=False)
    frames, peds = tracks[:, 0].astype(int), tracks[:, 1].astype(int)
    for scene in scenes:  # the windows: 21 of the primary's frames in a row, the converter's stride of 2
        own = np.sort(frames[peds == scene.primary])
        start = int(np.flatnonzero(own == scene.start_frame)[0])
        assert own[start + 20] == scene.end_frame and start % 2 == 0
    assert len(scenes) == 3 * 10 + 5  # 40 rows: starts 0, 2, ..., 18; 30 rows: 0, ..., 8
    wanted = set()
    for scene in scenes:
        own = (peds == scene.primary) & (frames >= scene.start_frame) & (frames <= scene.end_frame)
        wanted |= set(frames[own].tolist())
    reference = np.flatnonzero(np.isin(frames, sorted(wanted)))
    reference = reference[np.argsort(frames[reference], kind="stable")]
    np.testing.assert_array_equal(scene_track_rows(scenes, tracks), reference)


def test_a_scene_that_ends_before_it_starts_is_refused():
    """Its search bounds cross (lo > hi); only lo == hi was refused: its file failed validation."""
    from predictors.data.trajnet_scenes import SceneSpec, scene_track_rows

    tracks = walkers(n_steps=21, peds=(1,))
    with pytest.raises(ValueError, match="scene 0: primary 1 has no row in frames 100-50"):
        scene_track_rows([SceneSpec(0, 1, 100, 50)], tracks)


def test_a_write_that_fails_half_way_leaves_no_file(tmp_path, monkeypatch):
    import predictors.data.trajnet_scenes as trajnet_scenes

    calls = []

    def failing(row):
        calls.append(row)
        if len(calls) == 5:
            raise OSError("disk full")
        return "{}"

    monkeypatch.setattr(trajnet_scenes, "trajnet", failing)
    with pytest.raises(OSError, match="disk full"):
        write_ndjson(tmp_path / "x.ndjson", [SceneSpec(0, 1, 0, 200)], walkers())
    assert list(tmp_path.iterdir()) == []  # neither the file nor its temporary


def test_a_preparation_killed_in_its_self_check_leaves_nothing_the_next_does_not_remove(tmp_path):
    """The self-check's scratch was a folder in the temp directory: a preparation killed there (``kill``,
    a timeout) left a crowdmpc-selfcheck-* folder that nothing removes. It is inside the staging folder,
    which the next preparation removes."""
    import os
    import subprocess
    import sys

    raw = write_tiny_ewap(tmp_path / "data")
    reference = tmp_path / "data" / "reference.ndjson"
    reference.write_text("")
    temp, out = tmp_path / "tmp", tmp_path / "prepared"
    temp.mkdir()
    killed_in_the_check = (
        "import os, signal, sys\n"
        "from pathlib import Path\n"
        "from predictors.data import prepare\n"
        "from predictors.data.selfcheck import Reference\n"
        "def killed(*args, workdir, **kwargs):\n"
        "    os.kill(os.getpid(), signal.SIGKILL)\n"
        "prepare.compare_with_reference = killed\n"
        "refs = {'biwi_eth': Reference(Path(sys.argv[3]), 'ref', compare_tags=False)}\n"
        "prepare.prepare_ewap(sys.argv[1], sys.argv[2], categorize_scenes=False, references=refs)\n"
    )
    env = {**os.environ, "TMPDIR": str(temp), "PYTHONPATH": str(Path(__file__).parents[2])}
    args = [sys.executable, "-c", killed_in_the_check, str(raw), str(out), str(reference)]
    assert subprocess.run(args, env=env, capture_output=True).returncode == -9
    assert list(temp.iterdir()) == []
    prepare_ewap(raw, out, categorize_scenes=False, log=lambda msg: None)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data", "prepared", "tmp"]
