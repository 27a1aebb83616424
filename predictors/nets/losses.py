"""Training losses on predicted displacements and the GAN's variety loss.

``gaussian_nll`` is the plain bivariate-normal negative log-likelihood of Social-LSTM, not TrajNet++'s
``lstm/loss.py`` ``PredictionLoss``, which mixes that normal with a wide one and a flat background
(``-log(0.01 + 0.2 N(mu, 3) + 0.79 N(mu, sigma, rho))``) to bound the cost of an outlier; the shipped models
were trained with this one.
"""

from __future__ import annotations

import math

import torch

from predictors.errors import PredictorError

# What one step's miss costs in the variety loss: its Euclidean distance, or that distance squared (Social
# GAN's ``l2_loss(..., mode="raw")``)
VARIETY_ERRORS = ("distance", "squared")


def gaussian_nll(params: torch.Tensor, target: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """Mean negative log-likelihood of ``target`` (..., 2) under the bivariate normals ``params`` (..., 5).

    ``params`` = (mu_x, mu_y, sigma_x, sigma_y, rho) as ``nets.social_lstm.gaussian_head`` bounds them;
    ``weight`` (...) selects the entries that count (e.g. the primary agent's valid steps).
    """
    mu, sigma, rho = params[..., :2], params[..., 2:4], params[..., 4]
    z = (target - mu) / sigma
    one_minus_rho2 = 1 - rho**2
    quad = (z[..., 0] ** 2 + z[..., 1] ** 2 - 2 * rho * z[..., 0] * z[..., 1]) / (2 * one_minus_rho2)
    log_norm = (
        math.log(2 * math.pi) + torch.log(sigma[..., 0] * sigma[..., 1]) + 0.5 * torch.log(one_minus_rho2)
    )
    return _weighted_mean(log_norm + quad, weight)


def l2_loss(mean: torch.Tensor, target: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """Mean Euclidean distance between predicted and true displacements (or positions)."""
    return _weighted_mean(torch.linalg.vector_norm(mean - target, dim=-1), weight)


def variety_loss(
    samples: torch.Tensor, target: torch.Tensor, weight: torch.Tensor, error: str = "distance"
) -> torch.Tensor:
    """Best-of-k (Gupta et al. 2018): ``samples`` (k, B, T, 2), ``target`` (B, T, 2), ``weight`` (B, T).

    For each scene only the sample closest to the truth is penalised, by its error over the weighted steps
    summed and divided by the weights' sum (Social GAN's loss mask). ``error`` "distance" takes each step's
    Euclidean distance (the sample of least displacement error, ADE); "squared" its square summed over x
    and y, Social GAN's ``l2_loss(..., mode="raw")``, under which one large miss costs more than several
    small ones of the same total distance. Social GAN's code applies it to the displacements and sums its
    scenes; here both errors are of positions and averaged over the scenes, so that the batch size leaves
    the balance with the (averaged) adversarial loss alone.
    """
    if error not in VARIETY_ERRORS:
        raise PredictorError(f"variety error {error!r} is not one of {list(VARIETY_ERRORS)}")
    miss = samples - target[None]
    step = torch.linalg.vector_norm(miss, dim=-1) if error == "distance" else miss.square().sum(dim=-1)
    per_scene = (step * weight[None]).sum(dim=-1) / weight.sum(dim=-1).clamp(min=1)[None]  # (k, B)
    return per_scene.min(dim=0).values.mean()


def _weighted_mean(values: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    weight = weight.to(values.dtype)
    return (values * weight).sum() / weight.sum().clamp(min=1)
