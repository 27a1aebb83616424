"""CPU smoke tests of the LightningModules: ``fast_dev_run`` on a tiny dataset the test writes itself."""

from __future__ import annotations

import lightning as L
import pytest
import torch

from predictors.data.datamodule import TrajnetDataModule
from predictors.errors import PredictorError
from predictors.nets.social_gan import generator_config
from predictors.nets.social_lstm import SocialLSTMConfig
from predictors.training import GANModule, OptimConfig, SocialLSTMModule, make_module
from tests.predictors.samples import write_walk_file


@pytest.fixture
def tiny_data(tmp_path):
    path = write_walk_file(tmp_path / "walk.ndjson")
    return TrajnetDataModule([path], [path], [path], batch_size=2, seed=0)


def fast_dev_trainer() -> L.Trainer:
    return L.Trainer(
        fast_dev_run=True,
        accelerator="cpu",
        logger=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        enable_checkpointing=False,
    )


@pytest.mark.parametrize("pooling", ["none", "grid", "soft"])
@pytest.mark.parametrize("loss", ["gaussian", "l2"])
def test_social_lstm_module_fast_dev_run(tiny_data, pooling, loss):
    torch.manual_seed(0)
    module = make_module("social_lstm", SocialLSTMConfig(pooling=pooling), OptimConfig(loss=loss))
    assert isinstance(module, SocialLSTMModule)
    before = [p.detach().clone() for p in module.net.parameters()]
    trainer = fast_dev_trainer()
    trainer.fit(module, datamodule=tiny_data)
    assert any(not torch.equal(a, b) for a, b in zip(before, module.net.parameters(), strict=True))
    metrics = trainer.callback_metrics
    assert torch.isfinite(metrics["train_loss"]) and torch.isfinite(metrics["val_ade"])
    trainer.test(module, datamodule=tiny_data, verbose=False)
    assert torch.isfinite(trainer.callback_metrics["test_fde"])


def test_gan_module_fast_dev_run_updates_both_networks(tiny_data):
    torch.manual_seed(0)
    module = make_module("social_gan", generator_config(), OptimConfig(variety_k=3, top_k=4))
    assert isinstance(module, GANModule) and not module.automatic_optimization
    generator = [p.detach().clone() for p in module.net.parameters()]
    discriminator = [p.detach().clone() for p in module.discriminator.parameters()]
    trainer = fast_dev_trainer()
    trainer.fit(module, datamodule=tiny_data)
    assert any(not torch.equal(a, b) for a, b in zip(generator, module.net.parameters(), strict=True))
    assert any(
        not torch.equal(a, b) for a, b in zip(discriminator, module.discriminator.parameters(), strict=True)
    )
    metrics = trainer.callback_metrics
    for key in ("train_loss", "train_d_loss", "val_ade", "val_topk_ade"):
        assert torch.isfinite(metrics[key]), key


def test_model_step_shares_one_path_for_val_and_test(tiny_data):
    tiny_data.setup("test")
    batch = next(iter(tiny_data.test_dataloader()))
    module = SocialLSTMModule(SocialLSTMConfig().to_dict(), OptimConfig().__dict__).eval()
    with torch.no_grad():
        val, test = module.model_step(batch, "val"), module.model_step(batch, "test")
        train = module.model_step(batch, "train")
    assert all(torch.equal(val[k], test[k]) for k in val)
    # training feeds the ground truth back (teacher forcing), evaluation its own predictions
    assert not all(torch.equal(val[k], train[k]) for k in val if k in train)


def test_bad_options_are_refused():
    with pytest.raises(PredictorError, match="loss 'l1' is not one of"):
        OptimConfig(loss="l1")
    with pytest.raises(PredictorError, match="unknown model 'transformer'"):
        make_module("transformer", SocialLSTMConfig(), OptimConfig())
    with pytest.raises(PredictorError, match="needs noise_dim >= 1"):
        GANModule(SocialLSTMConfig().to_dict(), OptimConfig().__dict__)
