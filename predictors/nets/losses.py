"""Training losses on predicted displacements and the GAN's variety loss.

``gaussian_nll`` is the plain bivariate-normal negative log-likelihood of Social-LSTM, not TrajNet++'s
``lstm/loss.py`` ``PredictionLoss``, which mixes that normal with a wide one and a flat background
(``-log(0.01 + 0.2 N(mu, 3) + 0.79 N(mu, sigma, rho))``) to bound the cost of an outlier; the shipped models
were trained with this one.
"""

from __future__ import annotations

import math

import torch


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


def variety_loss(samples: torch.Tensor, target: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """Best-of-k (Gupta et al. 2018): ``samples`` (k, B, T, 2), ``target`` (B, T, 2), ``weight`` (B, T).

    For each scene only the sample closest to the truth (mean displacement error) is penalised.
    """
    error = torch.linalg.vector_norm(samples - target[None], dim=-1) * weight[None]
    per_scene = error.sum(dim=-1) / weight.sum(dim=-1).clamp(min=1)[None]  # (k, B)
    return per_scene.min(dim=0).values.mean()


def _weighted_mean(values: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    weight = weight.to(values.dtype)
    return (values * weight).sum() / weight.sum().clamp(min=1)
