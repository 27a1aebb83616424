"""Thin LightningModules around ``predictors.nets``: loss, optimiser, logging (STYLE.md example 6).

Only this module, ``predictors.data.datamodule`` and ``pipelines`` import Lightning. ``PredictorModule``
trains any net that keeps the step contract (``nets.contract``) of any registered model kind
(``predictors.models``); ``GANModule`` the adversarial ones; ``make_module`` picks. Both share one
``model_step(batch, stage)`` for train/val/test. Training follows TrajNet++ (``lstm/trainer.py``): Adam
(lr 1e-3, weight decay 1e-4), StepLR, neighbours teacher-forced and only the primary fed its own (detached)
predictions, loss on the primary's 12 predicted displacements. Validation and test predict every agent
recursively, as ``crowdmpc evaluate`` does, and log the primary's ADE/FDE (``val_ade`` selects the best
checkpoint).

Their optimiser's settings are ``OptimConfig`` (``predictors.optim_config``, exported here too).

The GAN (``GANModule``) optimises by hand (``automatic_optimization = False``): a generator step on the
variety (best-of-k) loss plus the adversarial loss, then a discriminator step on real vs generated
trajectories.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import asdict
from typing import TYPE_CHECKING, Any, cast

import lightning as L
import torch
import torch.nn.functional as F

from predictors.base import OBS_LEN, PRED_LEN, check_steps
from predictors.data.windows import SceneBatch
from predictors.errors import PredictorError
from predictors.metrics import ade, fde
from predictors.models import model_kind
from predictors.nets.contract import (
    check_step_contract,
    check_step_contract_in_float64,
    check_trainable,
    check_training_forward,
)
from predictors.nets.losses import gaussian_nll, l2_loss, variety_loss
from predictors.nets.rollout import teacher_forced_rollout
from predictors.nets.social_gan import Discriminator, DiscriminatorConfig
from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig
from predictors.optim_config import OptimConfig

if TYPE_CHECKING:
    from lightning.pytorch.core.optimizer import LightningOptimizer
    from torch.optim.lr_scheduler import LRScheduler


def primary_targets(batch: SceneBatch) -> tuple[torch.Tensor, torch.Tensor]:
    """The primary's true future positions (B, H, 2) and which of its steps are valid (B, H)."""
    return batch.future[:, :, 0], batch.mask[:, batch.obs_len :, 0]


class _PredictorModule(L.LightningModule):
    """What both modules share: validation and test through the subclass's ``model_step(batch, stage)``,
    and the wall time of every training epoch (``epoch_time_s``)."""

    def on_train_epoch_start(self) -> None:
        self._epoch_start = time.perf_counter()

    def on_train_epoch_end(self) -> None:
        self.log("epoch_time_s", time.perf_counter() - self._epoch_start, prog_bar=True)

    def on_save_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        # Lightning keeps no random state in its checkpoints: a resumed run would draw other GAN noise (and
        # dropout) than an uninterrupted one from the epoch on.
        checkpoint["crowdmpc_torch_rng"] = torch.get_rng_state()

    def on_load_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        # Only for a fit that resumes: load_from_checkpoint (no trainer) or a validate/test run restoring
        # weights replaced the caller's seeded random stream. Checkpoints from before it was kept have none.
        trainer = self._trainer
        if trainer is not None and trainer.state.fn == "fit" and "crowdmpc_torch_rng" in checkpoint:
            torch.set_rng_state(checkpoint["crowdmpc_torch_rng"])

    def model_step(self, batch: SceneBatch, stage: str) -> dict[str, torch.Tensor]:
        """The loss and metrics of ``batch``; each subclass defines it."""
        raise NotImplementedError

    @property
    def trained_loss(self) -> str:
        """The loss ``model_step`` trains on, as a checkpoint's ``training.optim.loss`` records it; each
        subclass defines it."""
        raise NotImplementedError

    def validation_step(self, batch: SceneBatch, batch_idx: int) -> None:
        self._log_eval(self.model_step(batch, "val"), "val", len(batch))

    def test_step(self, batch: SceneBatch, batch_idx: int) -> None:
        self._log_eval(self.model_step(batch, "test"), "test", len(batch))

    def predict_step(self, batch: SceneBatch, batch_idx: int) -> torch.Tensor:
        """``Trainer.predict``'s output: every agent's predicted positions (B, pred_len, Nmax, 2) in world
        coordinates (the scenes' own metres), NaN for an agent absent at the last observed step (padding
        included), whose prediction means nothing. As ``crowdmpc evaluate`` scores them: no teacher
        forcing, a GAN's generator at zero noise."""
        predicted = batch.to_world(self.predicted_positions(batch))
        present = batch.mask[:, batch.obs_len - 1]  # (B, Nmax)
        return predicted.masked_fill(~present[:, None, :, None], float("nan"))

    def predicted_positions(self, batch: SceneBatch) -> torch.Tensor:
        """Every agent's predicted positions (B, pred_len, Nmax, 2) in the scene frame; each subclass
        defines it."""
        raise NotImplementedError

    def _log_eval(self, out: dict, stage: str, batch_size: int) -> None:
        for key, value in out.items():
            self.log(f"{stage}_{key}", value, prog_bar=key == "ade", batch_size=batch_size)


def legacy_model(net_config: Mapping[str, Any]) -> str:
    """The model kind of a checkpoint written before modules recorded one (hyper-parameters
    ``net_config, optim_config`` only): those were Social-LSTMs, vanilla without pooling."""
    return "vanilla_lstm" if net_config.get("pooling") == "none" else "social_lstm"


def defines_forward(net: torch.nn.Module) -> bool:
    """Whether the net's class has its own training ``forward`` (``nn.Module``'s only raises)."""
    return type(net).forward is not torch.nn.Module.forward


class PredictorModule(_PredictorModule):
    """Any net that keeps the step contract (``predictors.nets.contract``), trained as TrajNet++ trains
    Social-LSTM: the net's own ``forward`` when its class defines one, else the generic teacher-forced
    rollout (``nets.rollout``); Gaussian NLL when the net has a Gaussian head and the loss is "gaussian",
    else L2 on the mean steps.

    ``net_config`` holds values over the kind's defaults (``kinds.ModelKind.config``); the hyper-parameters
    record the whole validated config. ``model=None`` is a checkpoint from before models were recorded
    (``legacy_model``).
    """

    def __init__(
        self,
        model: str | None = None,
        net_config: Mapping[str, Any] | None = None,
        optim_config: Mapping[str, Any] | None = None,
        obs_len: int = OBS_LEN,
        pred_len: int = PRED_LEN,
    ):
        super().__init__()
        values = dict(net_config or {})
        model = legacy_model(values) if model is None else model
        kind = model_kind(model)
        if kind.adversarial:
            raise PredictorError(f"model {model!r} is trained as a GAN (GANModule), not by PredictorModule")
        check_steps(obs_len, pred_len, f"model {model!r}")
        config = kind.config(values)
        self.optim = OptimConfig.from_dict(optim_config or {})
        self.save_hyperparameters(
            {
                "model": model,
                "net_config": kind.config_dict(config),
                "optim_config": asdict(self.optim),
                "obs_len": obs_len,
                "pred_len": pred_len,
            }
        )
        self.model_name = model
        self.net = kind.build_net(config)
        self.obs_len = obs_len
        self.pred_len = pred_len
        # Before any epoch: a net that breaks the contract would otherwise train on broadcast shapes (a
        # one-column step moves x and y alike) or fail deep in Lightning.
        check_trainable(self.net, f"model {model!r}")
        check_step_contract(self.net, f"model {model!r}", obs_len=obs_len)
        check_step_contract_in_float64(self.net, f"model {model!r}", obs_len=obs_len)
        if defines_forward(self.net):
            check_training_forward(self.net, f"model {model!r}", obs_len=obs_len, pred_len=pred_len)

    def rollout(self, positions: torch.Tensor, mask: torch.Tensor, teacher_forcing: bool):
        """(outputs (B, H, N, K), predicted positions (B, H, N, 2)) of the scenes."""
        if defines_forward(self.net):
            return self.net(positions, mask, self.obs_len, self.pred_len, teacher_forcing=teacher_forcing)
        return teacher_forced_rollout(
            self.net, positions, mask, self.obs_len, self.pred_len, teacher_forcing=teacher_forcing
        )

    def predicted_positions(self, batch: SceneBatch) -> torch.Tensor:
        return self.rollout(batch.positions, batch.mask, teacher_forcing=False)[1]

    @property
    def trained_loss(self) -> str:
        """The NLL ("gaussian") where it is asked of a net with a Gaussian head, else "l2" on the mean
        steps: a point head has no sigmas to score."""
        return "gaussian" if self.optim.loss == "gaussian" and self.net.head_type == "gaussian" else "l2"

    def model_step(self, batch: SceneBatch, stage: str) -> dict[str, torch.Tensor]:
        positions = batch.positions
        outputs, predicted = self.rollout(positions, batch.mask, teacher_forcing=stage == "train")
        truth, valid = primary_targets(batch)
        # TrajNet++ targets: true displacements of the primary (B, H, 2)
        previous = torch.cat([positions[:, self.obs_len - 1 : self.obs_len, 0], truth[:, :-1]], dim=1)
        target = truth - previous
        primary = outputs[:, :, 0]
        if self.trained_loss == "gaussian":
            loss = gaussian_nll(primary, target, valid)
        else:
            loss = l2_loss(primary[..., :2], target, valid)
        return {
            "loss": loss,
            "ade": ade(predicted[:, :, 0], truth).mean(),
            "fde": fde(predicted[:, :, 0], truth).mean(),
        }

    def training_step(self, batch: SceneBatch, batch_idx: int) -> torch.Tensor:
        out = self.model_step(batch, "train")
        self.log("train_loss", out["loss"], prog_bar=True, batch_size=len(batch))
        # the epoch's mean too: with fewer batches than log_every_n_steps the per-step value is never logged
        self.log("train_loss_epoch", out["loss"], on_step=False, on_epoch=True, batch_size=len(batch))
        return out["loss"]

    def configure_optimizers(self):
        optimizer = torch.optim.Adam(
            self.net.parameters(), lr=self.optim.lr, weight_decay=self.optim.weight_decay
        )
        scheduler = torch.optim.lr_scheduler.StepLR(optimizer, self.optim.step_size, self.optim.gamma)
        return [optimizer], [scheduler]


# The name before any net but Social-LSTM could be trained; the same class (note ``model`` comes first).
SocialLSTMModule = PredictorModule


class GANModule(_PredictorModule):
    """Social-GAN-like training with manual optimisation; ``self.net`` is the generator."""

    def __init__(
        self,
        net_config: dict,
        optim_config: dict,
        discriminator_config: dict | None = None,
        obs_len: int = OBS_LEN,
        pred_len: int = PRED_LEN,
    ):
        super().__init__()
        check_steps(obs_len, pred_len, "model 'social_gan'")
        self.save_hyperparameters()
        self.automatic_optimization = False
        config = SocialLSTMConfig.from_dict(net_config)
        if config.noise_dim < 1 or config.head != "point":
            raise PredictorError(f"the GAN generator needs noise_dim >= 1 and head 'point', got {config}")
        self.net = SocialLSTM(config)
        check_step_contract(self.net, "model 'social_gan'", obs_len=obs_len)
        self.discriminator = Discriminator(DiscriminatorConfig(**(discriminator_config or {})))
        self.optim = OptimConfig.from_dict(optim_config)
        self.obs_len = obs_len
        self.pred_len = pred_len

    def _generate(self, batch: SceneBatch, k: int, teacher_forcing: bool, zero_noise: bool = False):
        """``k`` generated futures of the primary: (k, B, H, 2)."""
        positions, mask = batch.positions, batch.mask
        batch_size, _, n_agents, _ = positions.shape
        repeat = (k, 1, 1, 1)
        noise = positions.new_zeros(k * batch_size, n_agents, self.net.config.noise_dim)
        if not zero_noise:
            noise.normal_()
        _, predicted = self.net(
            positions.repeat(*repeat),
            mask.repeat(k, 1, 1),
            self.obs_len,
            self.pred_len,
            teacher_forcing=teacher_forcing,
            noise=noise,
        )
        return predicted[:, :, 0].reshape(k, batch_size, self.pred_len, 2)

    def predicted_positions(self, batch: SceneBatch) -> torch.Tensor:
        noise = batch.positions.new_zeros(len(batch), batch.positions.shape[2], self.net.config.noise_dim)
        _, predicted = self.net(
            batch.positions, batch.mask, self.obs_len, self.pred_len, teacher_forcing=False, noise=noise
        )
        return predicted

    @property
    def trained_loss(self) -> str:
        return "variety+adversarial"  # whatever OptimConfig.loss says

    def _trajectory(self, batch: SceneBatch, future: torch.Tensor) -> torch.Tensor:
        return torch.cat([batch.positions[:, : self.obs_len, 0], future], dim=1)

    def model_step(self, batch: SceneBatch, stage: str) -> dict[str, torch.Tensor]:
        truth, valid = primary_targets(batch)
        if stage == "train":
            samples = self._generate(batch, self.optim.variety_k, teacher_forcing=True)
            variety = variety_loss(samples, truth, valid, self.optim.variety_error)
            fake_logits = self.discriminator(self._trajectory(batch, samples[0]))
            adversarial = F.binary_cross_entropy_with_logits(fake_logits, torch.ones_like(fake_logits))
            return {
                "loss": variety + self.optim.adversarial_weight * adversarial,
                "variety": variety,
                "adversarial": adversarial,
                "fake": samples[0].detach(),
            }
        deterministic = self._generate(batch, 1, teacher_forcing=False, zero_noise=True)[0]
        samples = self._generate(batch, self.optim.top_k, teacher_forcing=False)
        errors = ade(samples, truth[None])  # (k, B)
        best = errors.argmin(dim=0)
        index = torch.arange(len(batch), device=best.device)
        return {
            "ade": ade(deterministic, truth).mean(),
            "fde": fde(deterministic, truth).mean(),
            "topk_ade": errors[best, index].mean(),
            "topk_fde": fde(samples[best, index], truth).mean(),
        }

    def training_step(self, batch: SceneBatch, batch_idx: int) -> None:
        # configure_optimizers returns two optimizers, so Lightning hands back a list of two.
        opt_g, opt_d = cast("list[LightningOptimizer]", self.optimizers())
        # Generator first: its adversarial term runs through the discriminator, whose weights must not change
        # between that forward pass and this backward pass. (Its gradients on the discriminator are cleared
        # before the discriminator's own step.)
        out = self.model_step(batch, "train")
        opt_g.zero_grad()
        self.manual_backward(out["loss"])
        opt_g.step()

        d_loss = self.discriminator_loss(batch, out["fake"])
        opt_d.zero_grad()
        self.manual_backward(d_loss)
        opt_d.step()

        size = len(batch)
        self.log("train_loss", out["loss"], prog_bar=True, batch_size=size)
        self.log("train_loss_epoch", out["loss"], on_step=False, on_epoch=True, batch_size=size)
        self.log("train_variety", out["variety"], batch_size=size)
        self.log("train_adversarial", out["adversarial"], batch_size=size)
        self.log("train_d_loss", d_loss, prog_bar=True, batch_size=size)

    def discriminator_loss(self, batch: SceneBatch, fake: torch.Tensor) -> torch.Tensor:
        """Binary cross-entropy of the primary's true trajectories labelled real (1) and of the generated
        futures ``fake`` (B, H, 2) labelled fake (0), as Social GAN's discriminator is trained."""
        real_logits = self.discriminator(self._trajectory(batch, batch.future[:, :, 0]))
        fake_logits = self.discriminator(self._trajectory(batch, fake))
        return F.binary_cross_entropy_with_logits(
            real_logits, torch.ones_like(real_logits)
        ) + F.binary_cross_entropy_with_logits(fake_logits, torch.zeros_like(fake_logits))

    def on_train_epoch_end(self) -> None:
        super().on_train_epoch_end()
        # Two StepLR schedulers (configure_optimizers), so a list of plain LRSchedulers.
        for scheduler in cast("list[LRScheduler]", self.lr_schedulers()):
            scheduler.step()

    def configure_optimizers(self):
        opt_g = torch.optim.Adam(
            self.net.parameters(), lr=self.optim.lr, weight_decay=self.optim.weight_decay
        )
        opt_d = torch.optim.Adam(self.discriminator.parameters(), lr=self.optim.lr)
        schedulers = [
            torch.optim.lr_scheduler.StepLR(o, self.optim.step_size, self.optim.gamma) for o in (opt_g, opt_d)
        ]
        return [opt_g, opt_d], schedulers


def make_module(
    model: str, net_config: Any, optim: OptimConfig | Mapping[str, Any] | None
) -> PredictorModule | GANModule:
    """The LightningModule of a ``--model`` choice: ``net_config`` is the kind's config instance, or a dict
    of values over its defaults (None: the defaults), and so is ``optim`` of ``OptimConfig``'s; GAN training
    for adversarial kinds."""
    kind = model_kind(model)
    optim = optim if isinstance(optim, OptimConfig) else OptimConfig.from_dict({} if optim is None else optim)
    if isinstance(net_config, kind.config_class):
        config = net_config
    elif net_config is None or isinstance(net_config, Mapping):
        config = kind.config(net_config)
    else:
        raise PredictorError(
            f"{model}: expected a {kind.config_class.__name__} or a dict, got {type(net_config).__name__}"
        )
    values = kind.config_dict(config)
    if kind.adversarial:
        return GANModule(values, asdict(optim))
    return PredictorModule(model, values, asdict(optim))
