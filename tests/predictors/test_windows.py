import dataclasses
import math
import os

import numpy as np
import pytest
import torch

from predictors.data.windows import (
    TrajnetSceneDataset,
    collate_scenes,
    load_file_arrays,
    normalise,
    rotation_matrix,
)
from predictors.errors import DatasetFormatError, PredictorError
from tests.predictors.samples import walk_scene_records, write_lines, write_walk_file


def test_normalise_centres_on_the_primary_and_rotates():
    xy = np.full((3, 2, 2), np.nan)
    xy[:, 0] = [[0.0, 0.0], [1.0, 2.0], [2.0, 2.0]]
    xy[1, 1] = [1.0, 3.0]  # the neighbour is seen only at step 1, 1 m "above" the primary
    sample = normalise(xy, obs_len=2, angle=math.pi / 2)
    np.testing.assert_allclose(sample.origin, [1.0, 2.0])
    # a quarter turn counter-clockwise: +x -> +y, +y -> -x
    np.testing.assert_allclose(sample.positions[:, 0], [[2.0, -1.0], [0.0, 0.0], [0.0, 1.0]], atol=1e-6)
    np.testing.assert_allclose(sample.positions[1, 1], [-1.0, 0.0], atol=1e-6)
    assert sample.mask.tolist() == [[True, False], [True, True], [True, False]]
    assert (sample.positions[~sample.mask] == 0).all()


def test_normalise_needs_the_primary_at_the_last_observed_step():
    xy = np.zeros((4, 1, 2))
    xy[2] = np.nan
    with pytest.raises(PredictorError) as refused:
        normalise(xy, obs_len=3, angle=None)
    assert str(refused.value) == (
        "the primary pedestrian (agent 0) must be present at the last observed step 2; it is absent there "
        "(observed at steps [0, 1] of 0..2)"
    )
    with pytest.raises(PredictorError) as refused:
        normalise(xy, obs_len=3, angle=None, where="f.ndjson: scene 4")
    assert str(refused.value).startswith("f.ndjson: scene 4: the primary pedestrian (agent 0) must be")


def test_a_dataset_item_without_its_primary_names_the_file_and_scene(tmp_path):
    path = write_walk_file(tmp_path / "walk.ndjson")
    dataset = TrajnetSceneDataset([path])
    arrays = dataset.arrays[0]
    xy = arrays.xy.copy()  # the loaded arrays are cached for the process: spoil a copy
    xy[8, arrays.offsets[1]] = np.nan  # scene 1's primary (pedestrian 2) at the last observed step
    dataset.arrays[0] = dataclasses.replace(arrays, xy=xy)
    dataset[0]  # scene 0 is untouched
    with pytest.raises(PredictorError) as refused:
        dataset[1]
    assert str(refused.value) == (
        f"{path}: scene 1: the primary pedestrian (agent 0) must be present at the last observed step 8; it "
        "is absent there (observed at steps [0, 1, 2, 3, 4, 5, 6, 7] of 0..8)"
    )


def test_dataset_items_and_batches(tmp_path):
    dataset = TrajnetSceneDataset([write_walk_file(tmp_path / "walk.ndjson")])
    assert len(dataset) == 2
    item = dataset[0]
    assert item.positions.shape == (21, 3, 2) and item.positions.dtype == np.float32
    np.testing.assert_allclose(item.origin, [4.0, 0.0])  # primary at step 8: 8 x 0.5 m
    np.testing.assert_allclose(item.positions[8, 0], [0.0, 0.0])
    np.testing.assert_allclose(item.positions[20, 0], [6.0, 0.0])
    assert item.mask[:, 2].tolist() == [True] * 3 + [False] * 18
    batch = collate_scenes([dataset[0], dataset[1]])
    assert batch.positions.shape == (2, 21, 3, 2) and batch.mask.shape == (2, 21, 3)
    assert batch.observed.shape == (2, 9, 3, 2) and batch.future.shape == (2, 12, 3, 2)
    assert len(batch) == 2
    # scene 1's primary is pedestrian 2; its agents are 2, 1, 3 in order of appearance
    np.testing.assert_allclose(batch.positions[1, 8, 1].numpy(), [0.0, -1.0])
    world = batch.to_world(batch.positions)
    np.testing.assert_allclose(world[0, 20, 0].numpy(), [10.0, 0.0], atol=1e-5)


def test_collate_pads_agents_with_zeros_and_false(tmp_path):
    records = walk_scene_records()
    lonely = [r for r in records if "scene" in r or r["track"]["p"] == 1]
    dataset = TrajnetSceneDataset(
        [write_lines(tmp_path / "lonely.ndjson", lonely), write_walk_file(tmp_path / "w.ndjson")]
    )
    batch = collate_scenes([dataset[0], dataset[1]])
    assert batch.positions.shape == (2, 21, 3, 2)
    assert not batch.mask[0, :, 1:].any() and (batch.positions[0, :, 1:] == 0).all()
    # a real agent's absent steps stay False too: the walk's third walker is seen at steps 0..2 only
    assert batch.mask[1, :, 2].tolist() == [True] * 3 + [False] * 18
    np.testing.assert_array_equal(batch.mask[1].numpy(), dataset[1].mask)


def test_to_world_undoes_a_rotation(tmp_path):
    # positions = (world - origin) @ R^T, so world = positions @ R + origin; an unrotated batch cannot tell
    # R from R^T. The walk's primary is at (0.5 t, 0) m, so at step 20 it is at (10, 0) in the world
    dataset = TrajnetSceneDataset([write_walk_file(tmp_path / "walk.ndjson")], augment=True, seed=3)
    item = dataset[0]
    assert not np.allclose(item.rotation, np.eye(2), atol=1e-2)  # the seed draws a real turn
    batch = collate_scenes([item])
    world = batch.to_world(batch.positions)
    np.testing.assert_allclose(world[0, 20, 0].numpy(), [10.0, 0.0], atol=1e-5)
    np.testing.assert_allclose(world[0, 0, 0].numpy(), [0.0, 0.0], atol=1e-5)


def test_augmentation_is_seeded_and_keeps_distances(tmp_path):
    path = write_walk_file(tmp_path / "walk.ndjson")
    a = TrajnetSceneDataset([path], augment=True, seed=3)
    b = TrajnetSceneDataset([path], augment=True, seed=3)
    c = TrajnetSceneDataset([path], augment=True, seed=4)
    draws_a = [a[0, epoch].rotation for epoch in range(3)]
    draws_b = [b[0, epoch].rotation for epoch in range(3)]
    for x, y in zip(draws_a, draws_b, strict=True):
        np.testing.assert_allclose(x, y)
    assert not np.allclose(draws_a[0], draws_a[1])  # a new angle in every epoch
    np.testing.assert_array_equal(a[0].rotation, a[0, 0].rotation)  # and the same on a second fetch
    np.testing.assert_array_equal(a[0, 2].rotation, draws_a[2])
    assert not np.allclose(draws_a[0], c[0].rotation)
    item = a[0]
    np.testing.assert_allclose(item.rotation @ item.rotation.T, np.eye(2), atol=1e-6)
    gap = np.linalg.norm(item.positions[:, 0] - item.positions[:, 1], axis=-1)
    np.testing.assert_allclose(gap, 1.0, atol=1e-5)  # the two walkers stay 1 m apart
    np.testing.assert_allclose(rotation_matrix(0.0), np.eye(2))


def test_obs_and_pred_lengths_take_the_end_of_the_scene(tmp_path):
    dataset = TrajnetSceneDataset([write_walk_file(tmp_path / "walk.ndjson")], obs_len=8, pred_len=12)
    item = dataset[0]
    assert item.positions.shape[0] == 20
    # the prediction is always the scene's last 12 steps, so scene step 8 stays the last observed one
    np.testing.assert_allclose(item.origin, [4.0, 0.0])
    with pytest.raises(PredictorError, match="obs_len"):
        TrajnetSceneDataset([tmp_path / "walk.ndjson"], obs_len=10, pred_len=12)
    # one observed step gives no velocity: every predictor needs two
    with pytest.raises(PredictorError, match="^a scene dataset: need integers obs_len >= 2"):
        TrajnetSceneDataset([tmp_path / "walk.ndjson"], obs_len=1, pred_len=12)
    # a YAML file's "9" met a bare TypeError ("'<' not supported between instances of 'str' and 'int'")
    with pytest.raises(PredictorError, match=r"^a scene dataset: .*got obs_len='9', pred_len=12$"):
        TrajnetSceneDataset([tmp_path / "walk.ndjson"], obs_len="9")  # type: ignore[arg-type]


def test_file_arrays_are_cached_in_memory_and_on_disk(tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    monkeypatch.setenv("CROWDMPC_CACHE", str(cache))
    path = write_walk_file(tmp_path / "walk.ndjson")
    arrays = load_file_arrays(path)
    assert arrays.offsets.tolist() == [0, 3, 6] and arrays.xy.shape == (21, 6, 2)
    assert load_file_arrays(path) is arrays
    stored = list((cache / "scenes").glob("*.npz"))
    assert len(stored) == 1
    from predictors.data import windows

    windows._MEMORY.clear()
    again = load_file_arrays(path)
    np.testing.assert_array_equal(again.xy, arrays.xy)


def test_file_arrays_show_progress_while_built(tmp_path, monkeypatch, capsys):
    """The first read of a file of dense crowds is a minute of Reader work (50 s for 9 840 scenes of 177
    agents), which `crowdmpc train` spent printing nothing: a bar over the scenes while they are built, and
    none for a file served from the cache."""
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    path = write_walk_file(tmp_path / "walk.ndjson")
    assert len(load_file_arrays(path, progress=True)) == 2
    assert "reading walk.ndjson" in capsys.readouterr().err
    assert len(load_file_arrays(path, progress=True)) == 2
    assert "reading" not in capsys.readouterr().err


def test_the_cache_is_keyed_by_content_and_scene_length(tmp_path, monkeypatch):
    """A file rewritten in place (same size) is read anew, and a scene length the file does not have is
    refused, from memory or from disk, never served from the other length's arrays."""
    from predictors.data import windows

    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    path = write_walk_file(tmp_path / "walk.ndjson")
    assert load_file_arrays(path).xy[20, 0].tolist() == [10.0, 0.0]  # the primary at 0.5 m per step
    text = path.read_text()
    path.write_text(text.replace('"x": 10.0', '"x": 20.0'))  # the same number of bytes
    os.utime(path, ns=(path.stat().st_atime_ns, path.stat().st_mtime_ns + 10**9))  # a later write
    assert load_file_arrays(path).xy[20, 0].tolist() == [20.0, 0.0]
    held = [key for key in windows._MEMORY if key[0] == str(path.resolve())]
    assert len(held) == 1  # the earlier version let go, not held beside the new one
    for clear in (False, True):  # from memory, then from the disk cache alone
        if clear:
            windows._MEMORY.clear()
        with pytest.raises(DatasetFormatError, match="has 21 frames, need 20"):
            load_file_arrays(path, scene_length=20)


def test_scene_ids_are_the_files_and_a_damaged_cache_entry_is_rebuilt(tmp_path, monkeypatch):
    from predictors.data import windows

    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    path = write_lines(tmp_path / "four.ndjson", walk_scene_records(sid=4))
    assert load_file_arrays(path).scene_ids.tolist() == [4]  # as in the file, not a count from 0
    [entry] = (tmp_path / "cache" / "scenes").glob("*.npz")
    np.savez(entry, other=np.zeros(1))  # an entry without the arrays (an older layout, a crash)
    windows._MEMORY.clear()
    assert load_file_arrays(path).scene_ids.tolist() == [4]


@pytest.mark.parametrize("damage", ["cut in half", "zip garbage", "a flipped byte"])
def test_a_damaged_cache_entry_of_any_kind_is_rebuilt(damage, tmp_path, monkeypatch):
    """A cut or garbled .npz raises zipfile.BadZipFile, which the rebuild did not catch: every later
    `train` on the file ended in that traceback until the cache was cleared by hand."""
    from predictors.data import windows

    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    path = write_walk_file(tmp_path / "walk.ndjson")
    arrays = load_file_arrays(path)
    [entry] = (tmp_path / "cache" / "scenes").glob("*.npz")
    good = entry.read_bytes()
    spoilt = {
        "cut in half": good[: len(good) // 2],
        "zip garbage": b"PK\x03\x04" + b"x" * 100,  # a zip's magic, then nothing of a zip
        "a flipped byte": good[:200] + bytes([good[200] ^ 0xFF]) + good[201:],  # in xy's data: bad CRC
    }[damage]
    entry.write_bytes(spoilt)
    windows._MEMORY.clear()
    np.testing.assert_array_equal(load_file_arrays(path).xy, arrays.xy)
    with np.load(entry) as rebuilt:  # rebuilt in place
        np.testing.assert_array_equal(rebuilt["xy"], arrays.xy)
    assert sorted(p.name for p in entry.parent.iterdir()) == [entry.name]  # no temporary file left


@pytest.mark.parametrize("field", ["scene_ids", "offsets"])
def test_a_cache_entry_whose_arrays_do_not_fit_together_is_rebuilt(field, tmp_path, monkeypatch):
    """Arrays of the right names but the wrong shapes (a 0-d scene_ids made len() raise a TypeError past the
    rebuild; offsets that do not start at 0 would slice another scene's rows) are a damaged entry too."""
    from predictors.data import windows

    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    path = write_walk_file(tmp_path / "walk.ndjson")
    arrays = load_file_arrays(path)
    [entry] = (tmp_path / "cache" / "scenes").glob("*.npz")
    bad = {"xy": arrays.xy, "offsets": arrays.offsets, "scene_ids": arrays.scene_ids}
    shifted = arrays.offsets + (np.arange(arrays.offsets.size) == 0)  # starts at 1, ends where it did
    bad[field] = np.int64(7) if field == "scene_ids" else shifted
    with open(entry, "wb") as f:
        np.savez(f, **bad)
    windows._MEMORY.clear()
    np.testing.assert_array_equal(load_file_arrays(path).offsets, arrays.offsets)


def test_processes_sharing_the_cache_write_through_their_own_temporary_files(tmp_path, monkeypatch):
    """The temporary name was the same for every process: two runs building one entry at once wrote into
    the same file, and one could rename the other's half-written file into place."""
    from predictors.data import windows

    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    path = write_walk_file(tmp_path / "walk.ndjson")
    used = []
    real_replace = windows.Path.replace

    def replace(self, target):
        used.append(self.name)
        return real_replace(self, target)

    monkeypatch.setattr(windows.Path, "replace", replace)
    for pid in (101, 202):  # two processes, one after the other
        monkeypatch.setattr(os, "getpid", lambda pid=pid: pid)
        windows._MEMORY.clear()
        for entry in (tmp_path / "cache" / "scenes").glob("*.npz"):
            entry.unlink()
        load_file_arrays(path)
    assert len(used) == 2 and used[0] != used[1]


def test_dataset_rejects_short_scenes(tmp_path):
    records = walk_scene_records()
    records[0]["scene"]["e"] = 190
    with pytest.raises(DatasetFormatError, match="has 20 frames, need 21"):
        TrajnetSceneDataset([write_lines(tmp_path / "short.ndjson", records[:-3])])


def test_batch_to_device_returns_a_batch(tmp_path):
    dataset = TrajnetSceneDataset([write_walk_file(tmp_path / "walk.ndjson")])
    batch = collate_scenes([dataset[0]]).to(torch.device("cpu"))
    assert batch.positions.device.type == "cpu" and batch.obs_len == 9


def test_epoch_shuffle_is_a_function_of_seed_and_epoch():
    """A permutation of every item per epoch, each keyed (index, epoch); set_epoch alone decides the
    order, as Lightning's resume needs (it calls set_epoch after restoring the epoch)."""
    from predictors.data.windows import EpochShuffle

    class Items:
        def __len__(self) -> int:
            return 50

    sampler = EpochShuffle(Items(), seed=3)  # type: ignore[arg-type]
    orders = []
    for epoch in (0, 1, 0):
        sampler.set_epoch(epoch)
        keys = list(sampler)
        assert {e for _, e in keys} == {epoch} and sorted(i for i, _ in keys) == list(range(50))
        orders.append([i for i, _ in keys])
    assert orders[0] == orders[2] and orders[0] != orders[1]
    assert len(sampler) == 50 and [i for i, _ in EpochShuffle(Items(), seed=4)] != orders[0]  # type: ignore[arg-type]


@pytest.mark.parametrize("reader", ["dataset", "evaluate"])
def test_scenes_at_another_frame_rate_are_refused(tmp_path, reader, monkeypatch):
    """The nets learn and are scored on displacements per 0.4 s step: a 25 fps file would train on steps ten
    times shorter without a word. A scene row without "fps" passes, as the format allows."""
    from predictors.evaluate import load_eval_scenes

    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    records = walk_scene_records()
    records[0]["scene"]["fps"] = 25.0
    path = write_lines(tmp_path / "fast.ndjson", records)
    read = (lambda p: TrajnetSceneDataset([p])) if reader == "dataset" else load_eval_scenes
    with pytest.raises(DatasetFormatError, match=r"fast.ndjson:1: scene 0 is sampled at 25.0 fps, but the "):
        read(path)
    records[0]["scene"]["fps"] = 2.5000001  # a writer's rounding is no other frame rate
    assert len(read(write_lines(tmp_path / "rounded.ndjson", records))) == 1
    del records[0]["scene"]["fps"]
    assert len(read(write_lines(tmp_path / "plain.ndjson", records))) == 1


def test_a_cache_entry_write_interrupted_leaves_no_temporary(tmp_path, monkeypatch):
    """A Ctrl-C while an entry was written (seconds for a large synthetic set) left its ``.tmp`` in the
    cache for good: only an OSError removed it."""
    from predictors.data import windows

    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    path = write_walk_file(tmp_path / "walk.ndjson")

    def interrupted(handle, **arrays):
        handle.write(b"half an entry")
        raise KeyboardInterrupt

    monkeypatch.setattr(windows.np, "savez", interrupted)
    with pytest.raises(KeyboardInterrupt):
        load_file_arrays(path)
    assert list((tmp_path / "cache" / "scenes").iterdir()) == []


@pytest.mark.parametrize("given", [str, lambda path: path])
def test_a_lone_path_given_to_the_dataset_is_one_line(tmp_path, given):
    # a str was read letter by letter ("/: is a directory, not a data file"), a Path met "'PosixPath' object
    # is not iterable"; TrajnetDataModule refused both for itself, the dataset it builds did not
    path = write_walk_file(tmp_path / "walk.ndjson")
    with pytest.raises(
        PredictorError, match=r"^files is a list of paths, got the single path '.*walk\.ndjson'"
    ):
        TrajnetSceneDataset(given(path))
    assert len(TrajnetSceneDataset([given(path)])) == len(TrajnetSceneDataset([path]))
