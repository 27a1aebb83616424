"""``--batching by_size`` (predictors/data/batching.py): hand-checkable buckets, every item once an epoch,
a function of (seed, epoch) alone, and the data module's default batches unchanged."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from predictors.data.batching import BATCHINGS, BySizeBatches
from predictors.data.datamodule import TrajnetDataModule
from predictors.data.windows import EpochShuffle, TrajnetSceneDataset, collate_scenes
from predictors.errors import PredictorError
from tests.predictors.samples import write_crowds, write_walk_file


def padding_fraction(batches: list[list[int]], sizes: np.ndarray) -> float:
    """Padded agent slots over real ones: each batch holds ``len(batch) * max size`` slots
    (``collate_scenes`` pads to the largest scene), of which ``sum(sizes)`` are scenes' agents."""
    slots = sum(len(batch) * int(np.max(sizes[batch])) for batch in batches)
    real = sum(int(np.sum(sizes[batch])) for batch in batches)
    return (slots - real) / real


class Items:
    def __init__(self, n: int):
        self.n = n

    def __len__(self) -> int:
        return self.n


def batches(sizes, batch_size: int, bucket_batches: int, seed: int = 0, epoch: int = 0) -> list[list[int]]:
    shuffle = EpochShuffle(Items(len(sizes)), seed)  # type: ignore[arg-type]
    shuffle.set_epoch(epoch)
    sampler = BySizeBatches(shuffle, np.asarray(sizes), batch_size, bucket_batches)
    keys = list(sampler)
    assert len(keys) == len(sampler) and {e for batch in keys for _, e in batch} == {epoch}
    return [[i for i, _ in batch] for batch in keys]


def test_one_bucket_of_the_whole_epoch_pairs_the_equal_sizes():
    """Twelve items, two of each size 0..5 (item i has size i // 2), batches of two, one bucket over all:
    every batch is a pair of equal size, {2k, 2k + 1}, in some order of the pairs."""
    sizes = [i // 2 for i in range(12)]
    got = batches(sizes, batch_size=2, bucket_batches=6)
    assert sorted(sorted(batch) for batch in got) == [[2 * k, 2 * k + 1] for k in range(6)]
    assert padding_fraction(got, np.asarray(sizes)) == 0.0


def test_every_item_comes_once_an_epoch_in_as_many_batches_as_shuffled():
    """23 items in batches of 4: six batches, one of them short (the last chunk's last one)."""
    sizes = np.random.default_rng(1).integers(1, 30, size=23)
    for bucket_batches in (1, 2, 3, 100):
        for epoch in (0, 1, 5):
            got = batches(sizes, 4, bucket_batches, seed=7, epoch=epoch)
            assert sorted(i for batch in got for i in batch) == list(range(23))
            assert sorted(len(batch) for batch in got) == [3, 4, 4, 4, 4, 4]


def test_batches_are_the_sorted_chunks_of_the_shuffled_order():
    """What the docstring says, recomputed: the epoch's EpochShuffle order, in chunks of bucket_batches x
    batch_size, each sorted by size (ties in shuffled order) and cut; only the batches' order differs."""
    sizes = np.random.default_rng(2).integers(1, 6, size=40)  # many ties
    shuffle = EpochShuffle(Items(40), seed=3)  # type: ignore[arg-type]
    shuffle.set_epoch(2)
    order = [i for i, _ in shuffle]
    expected = []
    for start in range(0, 40, 12):  # bucket_batches 3 x batch_size 4
        chunk = sorted(order[start : start + 12], key=lambda i: sizes[i])  # stable, as the sampler's sort
        expected += [chunk[k : k + 4] for k in range(0, len(chunk), 4)]
    got = batches(sizes, 4, 3, seed=3, epoch=2)
    assert sorted(got) == sorted(expected) and got != expected
    for batch in got:  # within a batch, sizes ascend (sorted chunks cut in order)
        assert list(sizes[batch]) == sorted(sizes[batch])


def test_the_batches_are_a_function_of_seed_and_epoch():
    sizes = np.random.default_rng(3).integers(1, 20, size=50)
    first = batches(sizes, 5, 2, seed=1, epoch=0)
    assert batches(sizes, 5, 2, seed=1, epoch=0) == first  # reproducible
    assert batches(sizes, 5, 2, seed=1, epoch=1) != first  # a new order each epoch
    assert batches(sizes, 5, 2, seed=2, epoch=0) != first  # and each seed


def test_by_size_pads_less_than_shuffled():
    sizes = np.random.default_rng(4).integers(3, 29, size=200)
    order = [i for i, _ in EpochShuffle(Items(200), 0)]  # type: ignore[arg-type]
    shuffled = [order[k : k + 8] for k in range(0, 200, 8)]
    assert padding_fraction(batches(sizes, 8, 8), sizes) < padding_fraction(shuffled, sizes) / 3


def test_bad_arguments_are_refused():
    shuffle = EpochShuffle(Items(4))  # type: ignore[arg-type]
    with pytest.raises(PredictorError, match="one size per item"):
        BySizeBatches(shuffle, np.ones(3), 2)
    with pytest.raises(PredictorError, match="batch_size >= 1"):
        BySizeBatches(shuffle, np.ones(4), 0)
    with pytest.raises(PredictorError, match=r"batching 'size' is not one of \['shuffled', 'by_size'\]"):
        TrajnetDataModule(["a"], ["a"], ["a"], batching="size")


def test_agent_counts_are_the_agents_of_each_item(tmp_path):
    dataset = TrajnetSceneDataset([write_crowds(tmp_path / "crowds.ndjson"), write_walk_file(tmp_path / "w")])
    counts = dataset.agent_counts()
    assert counts.tolist() == [dataset[i].positions.shape[1] for i in range(len(dataset))]
    assert counts.tolist() == [3, 1, 2, 3, 4, 3, 3]


@pytest.mark.parametrize("batching", BATCHINGS)
def test_the_data_module_batches_every_scene_once_an_epoch(tmp_path, batching):
    path = write_crowds(tmp_path / "crowds.ndjson")
    data = TrajnetDataModule([path], [path], [path], batch_size=2, seed=5, batching=batching)
    data.setup("fit")
    loader = data.train_dataloader()
    seen = [tuple(sorted(int(n) for n in batch.mask.any(dim=1).sum(dim=1))) for batch in loader]
    assert len(seen) == 3 and sorted(n for batch in seen for n in batch) == [1, 2, 3, 3, 4]
    if batching == "by_size":
        # one chunk (16 batches of 2 >= 5 scenes): the sorted sizes 1 2 | 3 3 | 4, cut in pairs
        assert sorted(seen) == [(1, 2), (3, 3), (4,)]


def test_the_default_batches_are_those_of_before(tmp_path):
    """The data module's default ("shuffled") loader gives, epoch after epoch, the batches of the loader it
    built before --batching existed (a DataLoader over EpochShuffle): the same weights from the same seed."""
    path = write_crowds(tmp_path / "crowds.ndjson")
    data = TrajnetDataModule([path], [path], [path], batch_size=2, seed=5)
    data.setup("fit")
    loader = data.train_dataloader()
    dataset = data.datasets["train"]
    sampler = EpochShuffle(dataset, 5)
    before = DataLoader(dataset, batch_size=2, sampler=sampler, collate_fn=collate_scenes)
    for epoch in range(3):
        loader.sampler.set_epoch(epoch)  # type: ignore[attr-defined]
        sampler.set_epoch(epoch)
        for new, old in zip(loader, before, strict=True):
            assert torch.equal(new.positions, old.positions) and torch.equal(new.rotation, old.rotation)


def test_lightning_sets_the_epoch_of_the_by_size_batches(tmp_path):
    """Lightning calls set_epoch on a batch sampler's ``sampler`` only: each epoch's batches of a fit are
    that epoch's (their scenes rotated by the epoch's angles), not epoch 0's again and again (which a resumed
    run would repeat as well, and so resume "exactly")."""
    import lightning as L

    class Recorder(L.LightningModule):
        def __init__(self):
            super().__init__()
            self.weight = torch.nn.Parameter(torch.zeros(()))
            self.angles: dict[int, list[float]] = {}

        def training_step(self, batch, batch_idx):
            angles = torch.atan2(batch.rotation[:, 1, 0], batch.rotation[:, 0, 0]).tolist()
            self.angles.setdefault(self.current_epoch, []).extend(angles)
            return (self.weight * batch.positions.sum()) ** 2

        def configure_optimizers(self):
            return torch.optim.SGD(self.parameters(), lr=0.0)

    path = write_crowds(tmp_path / "crowds.ndjson")
    data = TrajnetDataModule([path], [path], [path], batch_size=2, seed=5, batching="by_size")
    module = Recorder()
    trainer = L.Trainer(
        max_epochs=3,
        accelerator="cpu",
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        limit_val_batches=0,
    )
    trainer.fit(module, datamodule=data)
    epochs = [sorted(module.angles[epoch]) for epoch in range(3)]
    assert len(epochs[0]) == 5 and epochs[0] != epochs[1] != epochs[2] != epochs[0]
