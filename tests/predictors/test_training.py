"""CPU smoke tests of the LightningModules: ``fast_dev_run`` on a tiny dataset the test writes itself."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import ClassVar

import lightning as L
import numpy as np
import pytest
import torch
import torch.nn.functional as F

from predictors.data.datamodule import TrajnetDataModule
from predictors.data.windows import SceneBatch
from predictors.errors import PredictorError
from predictors.models import load_plugin
from predictors.nets.losses import variety_loss
from predictors.nets.social_attention import SocialAttention
from predictors.nets.social_gan import generator_config
from predictors.nets.social_gru import SocialGRU, SocialGRUConfig
from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig
from predictors.optim_config import OptimConfig
from predictors.training import (
    GANModule,
    PredictorModule,
    SocialLSTMModule,
    defines_forward,
    make_module,
    primary_targets,
)
from tests.predictors.samples import write_walk_file


@pytest.fixture
def tiny_data(tmp_path):
    path = write_walk_file(tmp_path / "walk.ndjson")
    return TrajnetDataModule([path], [path], [path], batch_size=2, seed=0)


def fast_dev_trainer(precision: str | None = None) -> L.Trainer:
    return L.Trainer(
        fast_dev_run=True,
        accelerator="cpu",
        precision=precision,
        logger=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        enable_checkpointing=False,
    )


@pytest.mark.parametrize("pooling", ["none", "grid", "soft"])
@pytest.mark.parametrize("loss", ["gaussian", "l2"])
def test_social_lstm_module_fast_dev_run(tiny_data, pooling, loss):
    torch.manual_seed(0)
    model = "vanilla_lstm" if pooling == "none" else "social_lstm"  # a social_lstm pools
    module = make_module(model, SocialLSTMConfig(pooling=pooling), OptimConfig(loss=loss))
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
    module = SocialLSTMModule(
        net_config=SocialLSTMConfig().to_dict(), optim_config=OptimConfig().__dict__
    ).eval()
    with torch.no_grad():
        val, test = module.model_step(batch, "val"), module.model_step(batch, "test")
        train = module.model_step(batch, "train")
    assert all(torch.equal(val[k], test[k]) for k in val)
    # training feeds the ground truth back (teacher forcing), evaluation its own predictions
    assert not all(torch.equal(val[k], train[k]) for k in val if k in train)


def test_bad_options_are_refused():
    with pytest.raises(PredictorError, match="loss 'l1' is not one of"):
        OptimConfig(loss="l1")
    # a YAML file's 1e-3 is the str "1e-3": it met a bare TypeError ("'<=' not supported ..."); NaN passed
    with pytest.raises(PredictorError, match="^lr must be a number, got '1e-3'$"):
        OptimConfig(lr="1e-3")  # type: ignore[arg-type]
    with pytest.raises(PredictorError, match="^step_size must be an int, got 10.0$"):
        OptimConfig(step_size=10.0)  # type: ignore[arg-type]
    with pytest.raises(PredictorError, match="^lr must be finite, got nan$"):
        OptimConfig(lr=float("nan"))
    # numpy's scalars were taken before the type check, as SocialLSTMConfig's sizes and rates are
    assert OptimConfig(lr=np.float32(1e-3), step_size=np.int64(5), top_k=np.int64(3)).step_size == 5
    with pytest.raises(PredictorError, match="unknown model 'transformer'"):
        make_module("transformer", SocialLSTMConfig(), OptimConfig())
    with pytest.raises(PredictorError, match="needs noise_dim >= 1"):
        GANModule(SocialLSTMConfig().to_dict(), OptimConfig().__dict__)
    with pytest.raises(PredictorError, match="expected a SocialGRUConfig or a dict, got SocialLSTMConfig"):
        make_module("social_gru", SocialLSTMConfig(), OptimConfig())
    with pytest.raises(PredictorError, match=r"unknown social_gru config keys \['noise_dim'\]"):
        make_module("social_gru", {"noise_dim": 8}, OptimConfig())
    with pytest.raises(PredictorError, match="is trained as a GAN"):
        PredictorModule("social_gan")


# ---------------------------------------------------------------------------------------- any model kind
@pytest.mark.parametrize(
    ("model", "net_config", "net_class"),
    [
        ("social_gru", SocialGRUConfig(hidden_dim=16), SocialGRU),  # a config instance
        ("social_attention", {"heads": 2}, SocialAttention),  # values over the kind's defaults
    ],
)
def test_new_kinds_train_with_their_own_forward(tiny_data, model, net_config, net_class):
    torch.manual_seed(0)
    module = make_module(model, net_config, OptimConfig())
    assert isinstance(module, PredictorModule) and type(module.net) is net_class
    assert defines_forward(module.net) and module.net.head_type == "gaussian"
    assert module.hparams["net_config"] == module.net.config.to_dict()  # the whole config is recorded
    before = [p.detach().clone() for p in module.net.parameters()]
    trainer = fast_dev_trainer()
    trainer.fit(module, datamodule=tiny_data)
    assert any(not torch.equal(a, b) for a, b in zip(before, module.net.parameters(), strict=True))
    assert torch.isfinite(trainer.callback_metrics["train_loss"])
    assert torch.isfinite(trainer.callback_metrics["val_ade"])


@dataclass(frozen=True)
class ConstantStepConfig:
    gain: float = 1.0


class ConstantStepNet(torch.nn.Module):
    """A plugin that keeps only the step contract (no ``forward``): the next step is a linear map of the
    last one; the state is the last step."""

    config_class: ClassVar[type] = ConstantStepConfig
    head_type = "point"

    def __init__(self, config: ConstantStepConfig):
        super().__init__()
        self.config = config
        self.step_map = torch.nn.Linear(2, 2)

    def encode(self, positions, mask):
        last = (positions[:, -1] - positions[:, -2]) * mask[:, -1, :, None]
        return last, self.step_map(last * self.config.gain)

    def decode_step(self, last, prev, cur, neighbours):
        step = cur - prev
        return step, self.step_map(step * self.config.gain)


def test_a_net_without_forward_trains_through_the_generic_rollout(tiny_data):
    torch.manual_seed(0)
    kind = load_plugin(f"{__name__}:ConstantStepNet")
    module = make_module(kind.name, {"gain": 2.0}, OptimConfig(loss="gaussian"))  # point head: L2
    assert isinstance(module, PredictorModule) and not defines_forward(module.net)
    assert module.net.config == ConstantStepConfig(gain=2.0)
    before = module.net.step_map.weight.detach().clone()
    trainer = fast_dev_trainer()
    trainer.fit(module, datamodule=tiny_data)
    assert not torch.equal(before, module.net.step_map.weight)
    assert torch.isfinite(trainer.callback_metrics["train_loss"])


# ------------------------------------------------------------------------------------ older checkpoints
def _old_checkpoint(tiny_data, tmp_path, config: SocialLSTMConfig):
    """A checkpoint whose hyper-parameters are those of the old SocialLSTMModule (no ``model``)."""
    torch.manual_seed(0)
    trainer = L.Trainer(
        max_epochs=1,
        limit_train_batches=1,
        limit_val_batches=1,
        accelerator="cpu",
        logger=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        enable_checkpointing=False,
    )
    module = make_module("vanilla_lstm" if config.pooling == "none" else "social_lstm", config, OptimConfig())
    trainer.fit(module, datamodule=tiny_data)
    path = tmp_path / "old.ckpt"
    trainer.save_checkpoint(path)
    checkpoint = torch.load(path, weights_only=False)
    checkpoint["hyper_parameters"] = {
        "net_config": config.to_dict(),
        "optim_config": OptimConfig().__dict__,
        "obs_len": module.obs_len,
        "pred_len": module.pred_len,
    }
    torch.save(checkpoint, path)
    return path, module


@pytest.mark.parametrize(("pooling", "model"), [("grid", "social_lstm"), ("none", "vanilla_lstm")])
def test_old_checkpoints_load_as_social_or_vanilla_lstm(tiny_data, tmp_path, pooling, model):
    path, trained = _old_checkpoint(tiny_data, tmp_path, SocialLSTMConfig(pooling=pooling))
    loaded = PredictorModule.load_from_checkpoint(path, map_location="cpu")
    assert loaded.model_name == model and loaded.hparams["model"] == model
    assert type(loaded.net) is SocialLSTM and loaded.net.config == trained.net.config
    for a, b in zip(loaded.net.parameters(), trained.net.parameters(), strict=True):
        assert torch.equal(a, b)


def test_resume_from_an_old_checkpoint(tiny_data, tmp_path):
    path, _ = _old_checkpoint(tiny_data, tmp_path, SocialLSTMConfig())
    trainer = L.Trainer(
        max_epochs=2,
        limit_train_batches=1,
        limit_val_batches=1,
        accelerator="cpu",
        logger=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        enable_checkpointing=False,
    )
    module = make_module("social_lstm", SocialLSTMConfig(), OptimConfig())
    trainer.fit(module, datamodule=tiny_data, ckpt_path=str(path))
    assert trainer.current_epoch == 2
    assert torch.isfinite(trainer.callback_metrics["train_loss"])


class FinalX(torch.nn.Module):
    """A stand-in discriminator whose logit is the trajectory's final x: hand-computable losses."""

    def forward(self, trajectory: torch.Tensor) -> torch.Tensor:
        return trajectory[:, -1, 0]


def test_gan_losses_are_the_social_gan_definitions_by_hand():
    """Generator: variety + w * BCE(D(fake), real) = softplus(-logit); discriminator: BCE(D(real), real) +
    BCE(D(fake), fake) = softplus(-real logit) + softplus(fake logit). Every label and sign here survived
    mutation of the fast_dev_run test, which checks only that both nets change."""
    torch.manual_seed(0)
    module = make_module("social_gan", generator_config(), OptimConfig(variety_k=2, adversarial_weight=0.25))
    assert isinstance(module, GANModule)
    module.discriminator = FinalX()
    steps = torch.arange(21, dtype=torch.float32)[None, :, None, None]
    positions = torch.cat([0.4 * steps, torch.zeros_like(steps)], dim=-1) + torch.tensor([[[[-3.2, 0.0]]]])
    mask = torch.ones(1, 21, 1, dtype=torch.bool)
    batch = SceneBatch(positions, mask, torch.zeros(1, 2), torch.eye(2)[None], obs_len=9)
    out = module.model_step(batch, "train")
    fake_x = out["fake"][:, -1, 0]
    assert out["adversarial"].item() == pytest.approx(F.softplus(-fake_x).mean().item(), rel=1e-6)
    assert out["loss"].item() == pytest.approx(out["variety"].item() + 0.25 * out["adversarial"].item())
    real_x = positions[:, -1, 0, 0]  # 0.4 * 20 - 3.2 = 4.8 m
    assert real_x.item() == pytest.approx(4.8)
    d_loss = module.discriminator_loss(batch, out["fake"].detach())
    expected = F.softplus(-real_x).mean() + F.softplus(fake_x.detach()).mean()
    assert d_loss.item() == pytest.approx(expected.item(), rel=1e-6)


@pytest.mark.parametrize("precision", ["64-true", "bf16-mixed"])
def test_a_plain_trainer_trains_at_lightnings_precisions(tiny_data, precision):
    """Trainer(precision="64-true") refused the frozen SceneBatch (apply_to_collection rebuilds it), and
    bf16-mixed met a float32 share added into a bfloat16 pooling grid."""
    module = make_module("social_lstm", SocialLSTMConfig(hidden_dim=8, embedding_dim=8), OptimConfig())
    trainer = fast_dev_trainer(precision)
    trainer.fit(module, datamodule=tiny_data)
    assert torch.isfinite(trainer.callback_metrics["train_loss"])


def test_loading_a_checkpoint_leaves_the_callers_random_stream(tiny_data, tmp_path):
    """on_load_checkpoint restores the run's torch RNG for a fit that resumes, and only there: a notebook's
    load_from_checkpoint set the caller's stream to the run's (its next draws were the run's)."""
    path, _ = _old_checkpoint(tiny_data, tmp_path, SocialLSTMConfig())
    checkpoint = torch.load(path, weights_only=True)
    torch.manual_seed(999)
    checkpoint["crowdmpc_torch_rng"] = torch.get_rng_state()  # as a run's checkpoint holds it
    runs = torch.rand(3)
    torch.save(checkpoint, path)
    torch.manual_seed(123)
    PredictorModule.load_from_checkpoint(path, map_location="cpu")  # building the net draws its init
    after_load = torch.rand(3)
    torch.manual_seed(123)
    make_module("social_lstm", SocialLSTMConfig(), OptimConfig())
    assert not torch.equal(after_load, runs) and torch.equal(after_load, torch.rand(3))


def test_the_variety_error_is_checked_and_defaults_to_the_distance():
    assert OptimConfig().variety_error == "distance"
    with pytest.raises(
        PredictorError, match=r"^variety_error 'mse' is not one of \['distance', 'squared'\]$"
    ):
        OptimConfig(variety_error="mse")
    # hyper-parameters saved before the option (every shipped GAN's) train on the distance, as they did
    before = {k: v for k, v in OptimConfig().__dict__.items() if k != "variety_error"}
    module = GANModule(generator_config().to_dict(), before)
    assert module.optim.variety_error == "distance"


@pytest.mark.parametrize("error", ["distance", "squared"])
def test_the_gan_trains_on_the_variety_error_of_its_config(error):
    """The generator's variety term is variety_loss of the error asked for, over the samples it drew."""
    config = (
        OptimConfig(variety_k=3) if error == "distance" else OptimConfig(variety_k=3, variety_error=error)
    )
    module = make_module("social_gan", generator_config(), config)
    assert isinstance(module, GANModule)
    module.discriminator = FinalX()
    steps = torch.arange(21, dtype=torch.float32)[None, :, None, None]
    positions = torch.cat([0.4 * steps, 0.1 * steps**1.5], dim=-1)
    batch = SceneBatch(
        positions, torch.ones(1, 21, 1, dtype=torch.bool), torch.zeros(1, 2), torch.eye(2)[None], obs_len=9
    )
    torch.manual_seed(0)
    out = module.model_step(batch, "train")
    torch.manual_seed(0)
    samples = module._generate(batch, 3, teacher_forcing=True)
    truth, valid = primary_targets(batch)
    expected = variety_loss(samples, truth, valid, error)
    assert out["variety"].item() == pytest.approx(expected.item(), rel=1e-6)
    other = variety_loss(samples, truth, valid, "squared" if error == "distance" else "distance")
    assert out["variety"].item() != pytest.approx(other.item(), rel=1e-3)


def test_optim_config_stays_importable_from_training():
    """OptimConfig lived in predictors.training before predictors.optim_config: code written then (and
    docs/extending.md's example) still imports it from there."""
    from predictors import optim_config, training

    assert training.OptimConfig is optim_config.OptimConfig


@pytest.mark.parametrize(
    ("steps", "shown"),
    [
        ({"obs_len": 1}, "obs_len=1, pred_len=12"),  # was IndexError: index -2 is out of bounds
        ({"pred_len": 0}, "obs_len=9, pred_len=0"),  # was the contract check blaming the net's outputs
        ({"obs_len": "9"}, "obs_len='9', pred_len=12"),  # a YAML file's string: a bare TypeError
    ],
)
def test_the_modules_refuse_too_few_steps_in_one_line_naming_them(steps, shown):
    need = "need integers obs_len >= 2 (a displacement needs two observed steps) and pred_len >= 1"
    with pytest.raises(PredictorError, match=rf"^model 'social_lstm': {re.escape(need)}, got {shown}$"):
        PredictorModule("social_lstm", **steps)
    with pytest.raises(PredictorError, match=rf"^model 'social_gan': {re.escape(need)}, got {shown}$"):
        GANModule(generator_config().to_dict(), {}, **steps)


def test_an_optimiser_config_of_values_is_taken_or_refused_in_one_line():
    # make_module took an OptimConfig only: a dict or None met asdict()'s bare TypeError, and a module's
    # optim_config with a misspelt key OptimConfig's "unexpected keyword argument"
    module = make_module("social_lstm", None, {"lr": 5e-4})
    assert module.optim == OptimConfig(lr=5e-4)
    assert make_module("social_lstm", None, None).optim == OptimConfig()
    unknown = (
        r"^unknown optimiser config keys \['learning_rate'\]; expected a subset of \['adversarial_weight', "
    )
    with pytest.raises(PredictorError, match=unknown):
        make_module("social_lstm", None, {"learning_rate": 1e-3})
    with pytest.raises(PredictorError, match=unknown):
        PredictorModule("social_lstm", optim_config={"learning_rate": 1e-3})
    with pytest.raises(PredictorError, match=unknown):
        GANModule(generator_config().to_dict(), {"learning_rate": 1e-3})
    with pytest.raises(
        PredictorError, match="^an optimiser config is an OptimConfig or a dict of its fields"
    ):
        make_module("social_lstm", None, [("lr", 1e-3)])  # type: ignore[arg-type]


def test_an_optimiser_config_reads_as_the_nets_configs_do():
    # OptimConfig.from_dict repeated nets.config_checks.config_from_dict's rule in words of its own; it is
    # that rule now, with the str order it had for a dict built in Python whose keys are not all strings
    assert OptimConfig.from_dict({"lr": 5e-4}) == OptimConfig(lr=5e-4)
    with pytest.raises(
        PredictorError, match=r"^unknown optimiser config keys \[1, 'rate'\]; expected a subset"
    ):
        OptimConfig.from_dict({"rate": 1e-3, 1: 2, "lr": 1e-3})
