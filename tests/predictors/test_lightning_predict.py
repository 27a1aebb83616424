"""The modules and the data module as Lightning users drive them: ``Trainer.predict`` and
``load_from_checkpoint``, beside the ``fit``/``test`` of test_training.py."""

from __future__ import annotations

import lightning as L
import pytest
import torch

from pipelines.commands.train_resume import checkpoint_settings
from predictors.data.datamodule import TrajnetDataModule
from predictors.nets.social_gan import generator_config
from predictors.optim_config import OptimConfig
from predictors.training import GANModule, PredictorModule, make_module
from tests.predictors.samples import write_walk_file


def _trainer(**options) -> L.Trainer:
    return L.Trainer(
        accelerator="cpu", logger=False, enable_progress_bar=False, enable_model_summary=False, **options
    )


def _modules():
    torch.manual_seed(0)
    return {
        "vanilla_lstm": make_module("vanilla_lstm", None, OptimConfig()),
        "social_gan": make_module("social_gan", generator_config(), OptimConfig(top_k=2)),
    }


@pytest.mark.parametrize("model", ["vanilla_lstm", "social_gan"])
def test_predict_gives_world_positions_scored_as_test_scores_them(tmp_path, model):
    data = TrajnetDataModule(*[[write_walk_file(tmp_path / "walk.ndjson")]] * 3, batch_size=8, seed=0)
    module = _modules()[model]
    trainer = _trainer(enable_checkpointing=False)
    [predicted] = trainer.predict(module, datamodule=data)
    [scores] = trainer.test(module, datamodule=data, verbose=False)
    batch = next(iter(data.predict_dataloader()))
    assert predicted.shape == (2, 12, batch.positions.shape[2], 2)  # the walk file's two scenes
    # the primary's error against the recorded future, in the scenes' own metres: a rotation and a shift
    # keep distances, so its mean is the test ADE (a GAN's at zero noise, its deterministic ADE)
    truth = batch.to_world(batch.future)[:, :, 0]
    ade = torch.linalg.vector_norm(predicted[:, :, 0] - truth, dim=-1).mean()
    assert ade.item() == pytest.approx(scores["test_ade"], rel=1e-5)
    # an agent absent at the last observed step has no prediction: NaN, not a number that looks like one
    present = batch.mask[:, batch.obs_len - 1]
    assert not present.all()
    by_agent = predicted.permute(0, 2, 1, 3)  # (B, N, 12, 2)
    assert torch.isnan(by_agent[~present]).all()
    assert torch.isfinite(by_agent[present]).all()


def test_a_fitted_run_loads_back_its_module_and_its_data_module(tmp_path):
    path = write_walk_file(tmp_path / "walk.ndjson")
    data = TrajnetDataModule([path], [path], [path], batch_size=2, seed=3, batching="by_size")
    module = _modules()["vanilla_lstm"]
    trainer = _trainer(max_epochs=1, default_root_dir=tmp_path)
    trainer.fit(module, datamodule=data)
    [checkpoint] = tmp_path.rglob("*.ckpt")

    again = TrajnetDataModule.load_from_checkpoint(checkpoint)
    assert again.files == {"train": [str(path)], "val": [str(path)], "test": [str(path)]}
    assert (again.batch_size, again.seed, again.batching) == (2, 3, "by_size")
    loaded = PredictorModule.load_from_checkpoint(checkpoint)
    for a, b in zip(module.net.parameters(), loaded.net.parameters(), strict=True):
        assert torch.equal(a, b)

    # what a resume reads from the checkpoint (a run older than its settings file): the files either way
    held = torch.load(checkpoint, map_location="cpu", weights_only=True)
    files = {split: [str(path.resolve())] for split in ("train", "val", "test")}
    assert (
        checkpoint_settings(held["hyper_parameters"], held["datamodule_hyper_parameters"])["files"] == files
    )
    older = {"files": {split: [str(path)] for split in files}, "seed": 3, "batch_size": 2}
    assert checkpoint_settings(held["hyper_parameters"], older)["files"] == files


def test_gan_module_loads_back_from_its_checkpoint(tmp_path):
    path = write_walk_file(tmp_path / "walk.ndjson")
    module = _modules()["social_gan"]
    assert isinstance(module, GANModule)
    trainer = _trainer(max_epochs=1, default_root_dir=tmp_path)
    trainer.fit(module, datamodule=TrajnetDataModule([path], [path], [path], batch_size=2, seed=0))
    [checkpoint] = tmp_path.rglob("*.ckpt")
    loaded = GANModule.load_from_checkpoint(checkpoint)
    for a, b in zip(module.net.parameters(), loaded.net.parameters(), strict=True):
        assert torch.equal(a, b)
