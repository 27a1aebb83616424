"""CPU smoke test: the DataModule feeds a Lightning fit on a tiny dataset the test writes itself."""

import re
from pathlib import Path

import lightning as L
import numpy as np
import pytest
import torch

from predictors.data.datamodule import TrajnetDataModule
from predictors.data.windows import SceneBatch
from predictors.errors import PredictorError
from tests.predictors.samples import write_walk_file


class ConstantStepModel(L.LightningModule):
    """Predicts the primary's future as its last observed step repeated; learns a single scale."""

    def __init__(self):
        super().__init__()
        self.scale = torch.nn.Parameter(torch.zeros(()))
        self.seen: list[SceneBatch] = []

    def model_step(self, batch: SceneBatch) -> torch.Tensor:
        assert isinstance(batch, SceneBatch)
        self.seen.append(batch)
        step = batch.observed[:, -1, 0] - batch.observed[:, -2, 0]  # (B, 2)
        horizon = torch.arange(1, batch.future.shape[1] + 1, dtype=step.dtype)
        prediction = self.scale * horizon[None, :, None] * step[:, None, :]
        return ((prediction - batch.future[:, :, 0]) ** 2).sum(-1).mean()

    def training_step(self, batch, batch_idx):
        return self.model_step(batch)

    def validation_step(self, batch, batch_idx):
        self.log("val_loss", self.model_step(batch), batch_size=len(batch))

    def test_step(self, batch, batch_idx):
        self.log("test_loss", self.model_step(batch), batch_size=len(batch))

    def configure_optimizers(self):
        return torch.optim.SGD(self.parameters(), lr=0.01)


def test_fast_dev_run_on_a_tiny_dataset(tmp_path):
    path = write_walk_file(tmp_path / "walk.ndjson")
    data = TrajnetDataModule([path], [path], [path], batch_size=2, augment=True, seed=0)
    model = ConstantStepModel()
    trainer = L.Trainer(
        fast_dev_run=True,
        accelerator="cpu",
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
    )
    trainer.fit(model, datamodule=data)
    trainer.test(model, datamodule=data, verbose=False)
    assert len(model.seen) == 3  # one train, one val and one test batch
    assert model.seen[0].positions.shape == (2, 21, 3, 2)
    assert model.scale.item() != 0.0  # the optimiser stepped


@pytest.mark.parametrize(
    "change, message",
    [
        ({"val_files": "val.ndjson"}, "val_files is a list of paths, got the single path 'val.ndjson'"),
        ({"train_files": Path("a.ndjson")}, "train_files is a list of paths, got the single path 'a.ndjson'"),
        ({"batch_size": "8"}, "batch_size must be an int, got str '8'"),
        ({"num_workers": 1.0}, "num_workers must be an int, got float 1.0"),
        # these three reached the first training batch: "manual_seed expected a long, but got str",
        # numpy's "expected non-negative integer"; "no" was true and rotated the scenes
        ({"seed": "0"}, "seed must be an int, got str '0'"),
        ({"seed": -1}, "seed must be in 0..18446744073709551615 (a torch generator's range), got -1"),
        ({"augment": "no"}, "augment must be True or False, got str 'no'"),
    ],
)
def test_a_lone_path_or_a_count_of_another_type_is_one_line(tmp_path, change, message):
    # a str path was read letter by letter ("/: is a directory"), a str batch_size met a bare TypeError
    path = write_walk_file(tmp_path / "walk.ndjson")
    given = {"train_files": [path], "val_files": [path], "test_files": [path], "batch_size": 2} | change
    with pytest.raises(PredictorError, match=re.escape(message)):
        TrajnetDataModule(**given)


def test_a_numpy_seed_is_taken_as_the_same_int(tmp_path):
    # torch's generator refused np.int64 ("an integer is required") at the first training batch
    path = write_walk_file(tmp_path / "walk.ndjson")
    batches = []
    for seed in (np.int64(3), 3):
        data = TrajnetDataModule([path], [path], [path], batch_size=2, seed=seed)
        data.setup("fit")
        batches.append(next(iter(data.train_dataloader())))
        assert type(data.hparams["seed"]) is int
    assert torch.equal(batches[0].positions, batches[1].positions)


def test_training_batches_are_shuffled_and_rotated_reproducibly(tmp_path):
    path = write_walk_file(tmp_path / "walk.ndjson")

    def first_batch(seed):
        data = TrajnetDataModule([path], [path], [path], batch_size=2, seed=seed)
        data.setup("fit")
        return next(iter(data.train_dataloader()))

    a, b, c = first_batch(1), first_batch(1), first_batch(2)
    torch.testing.assert_close(a.positions, b.positions)
    assert not torch.allclose(a.rotation, c.rotation)
    data = TrajnetDataModule([path], [path], [path], batch_size=2)
    data.setup("validate")
    val = next(iter(data.val_dataloader()))
    torch.testing.assert_close(val.rotation, torch.eye(2).expand(2, 2, 2))
