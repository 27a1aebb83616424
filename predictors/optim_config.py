"""How a predictor net is optimised (``OptimConfig``): Adam's learning rate and weight decay, the StepLR
decay, the loss, and the GAN's best-of-k and adversarial settings, TrajNet++'s defaults, checked when made.
The LightningModules that train with it are ``predictors.training``, which still exports it."""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import asdict, dataclass

from predictors.errors import PredictorError
from predictors.nets.config_checks import config_from_dict
from predictors.nets.losses import VARIETY_ERRORS

LOSSES = ("gaussian", "l2")


@dataclass(frozen=True)
class OptimConfig:
    lr: float = 1e-3  # Adam learning rate [TrajNet++ 1e-3]
    weight_decay: float = 1e-4  # [TrajNet++ 1e-4]
    step_size: int = 10  # epochs between learning-rate decays by gamma [TrajNet++ 10]
    gamma: float = 0.1  # [torch StepLR default, as TrajNet++]
    loss: str = "gaussian"  # "gaussian" (TrajNet++ "pred") | "l2"; the GAN always uses variety + adversarial
    variety_k: int = 6  # GAN: samples per scene for the best-of-k loss [Social GAN: 20]
    adversarial_weight: float = 0.1  # GAN: weight of the generator's adversarial loss
    top_k: int = 20  # GAN: samples for the validation top-k ADE/FDE
    # GAN: what the best-of-k loss picks and penalises per scene (nets.losses.variety_loss): "distance", the
    # sample's mean Euclidean error (every shipped GAN), or "squared", its mean squared error [Social GAN]
    variety_error: str = "distance"

    @classmethod
    def from_dict(cls, values: object) -> OptimConfig:
        """``OptimConfig(**values)`` of a mapping of its field names (a module's ``optim_config``, a file's
        object); anything else, or an unknown key, is a PredictorError naming it where ``OptimConfig(**x)``
        raised a bare TypeError ("unexpected keyword argument", "argument after ** must be a mapping")."""
        if not isinstance(values, Mapping):
            raise PredictorError(
                f"an optimiser config is an OptimConfig or a dict of its fields, got {type(values).__name__}"
            )
        return config_from_dict(cls, dict(values), "optimiser")  # the nets' configs' rule and words

    def __post_init__(self):
        for key, value in asdict(self).items():  # "1e-3" from a YAML file met a bare TypeError below
            if key in ("loss", "variety_error"):
                continue
            whole = key in ("step_size", "variety_k", "top_k")
            # numpy's scalars (a sweep's np.arange steps) as the nets' configs take them
            if isinstance(value, bool) or not isinstance(value, numbers.Integral if whole else numbers.Real):
                raise PredictorError(f"{key} must be {'an int' if whole else 'a number'}, got {value!r}")
            if not math.isfinite(value):
                raise PredictorError(f"{key} must be finite, got {value!r}")
        if self.loss not in LOSSES:
            raise PredictorError(f"loss {self.loss!r} is not one of {list(LOSSES)}")
        if self.variety_error not in VARIETY_ERRORS:
            raise PredictorError(f"variety_error {self.variety_error!r} is not one of {list(VARIETY_ERRORS)}")
        if self.lr <= 0 or self.weight_decay < 0 or self.step_size < 1 or not 0 < self.gamma <= 1:
            raise PredictorError(
                f"need lr > 0, weight_decay >= 0, step_size >= 1 and 0 < gamma <= 1, got {asdict(self)}"
            )
        if self.variety_k < 1 or self.top_k < 1 or self.adversarial_weight < 0:
            raise PredictorError(
                f"need variety_k >= 1, top_k >= 1 and adversarial_weight >= 0, got {asdict(self)}"
            )
