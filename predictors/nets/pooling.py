"""Social pooling of neighbours' hidden states on a grid around each agent (Alahi et al. 2016, TrajNet++).

Two ways to put a neighbour in a cell:

* ``"grid"``: TrajNet++'s ``GridBasedPooling(type_='social')``: integer binning of the relative position, so
  the pooled vector is piecewise constant in positions (zero gradient almost everywhere). Where two
  neighbours share a cell their values are summed; TrajNet++ writes them by index assignment, so one of them
  (the later in memory order) silently wins. Summing is order-independent and is what the soft variant
  reduces to.
* ``"soft"``: bilinear ("tent") assignment of each neighbour over the four nearest cell centres, for a
  non-zero gradient with respect to the neighbours' positions (the coupled NLP needs it). A neighbour's
  weights sum to 1 between the outermost cell centres and fade to 0 half a cell beyond the grid's edge.

``predictors.export`` exports this code as it is; the hand-written twin kept as a cross-check,
``tests/predictors/handwritten/layers.py`` (``grid_cell_weights`` / ``grid_pool``), and this code compute the
relative coordinate with the same float operations so that hard binning agrees exactly.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

POOLINGS = ("none", "grid", "soft")


def cell_weights(
    positions: torch.Tensor, neighbours: torch.Tensor, *, cell_side: float, grid_size: int, soft: bool
) -> torch.Tensor:
    """Weight of neighbour ``j`` in cell ``c`` of agent ``i``: ``(B, N, N, C)``, ``C = grid_size**2``.

    ``positions`` (B, N, 2) metres; ``neighbours`` (B, N) bool or float: which agents may be pooled.
    Cell ``c = kx * grid_size + ky`` with ``kx`` along x, as in TrajNet++.
    """
    n_agents = positions.shape[1]
    # u[b, i, j] = (p_j - p_i) / cell_side + grid_size / 2, the same operations as the hand-written twin.
    u = (positions[:, None, :, :] - positions[:, :, None, :]) / cell_side + grid_size / 2
    k = torch.arange(grid_size, dtype=positions.dtype, device=positions.device)
    if soft:
        per_axis = torch.relu(1 - torch.abs(u[..., None] - (k + 0.5)))  # (B, N, N, 2, n)
    else:
        per_axis = ((u[..., None] >= k) & (u[..., None] < k + 1)).to(positions.dtype)
    weights = per_axis[..., 0, :, None] * per_axis[..., 1, None, :]  # (B, N, N, n, n)
    off_diagonal = 1 - torch.eye(n_agents, dtype=positions.dtype, device=positions.device)
    column = neighbours.to(positions.dtype)[:, None, :] * off_diagonal  # (B, N, N)
    return weights.reshape(*weights.shape[:3], grid_size * grid_size) * column[..., None]


class GridPooling(nn.Module):
    """Neighbours' hidden states, compressed to ``latent_dim``, summed per cell, then ``Linear + ReLU``."""

    def __init__(
        self, *, hidden_dim: int, latent_dim: int, out_dim: int, cell_side: float, grid_size: int, soft: bool
    ):
        super().__init__()
        self.cell_side = cell_side
        self.grid_size = grid_size
        self.soft = soft
        self.hidden_encoding = nn.Linear(hidden_dim, latent_dim)  # TrajNet++ `hidden_dim_encoding`
        self.embedding = nn.Linear(grid_size * grid_size * latent_dim, out_dim)

    def forward(
        self, hidden: torch.Tensor, positions: torch.Tensor, neighbours: torch.Tensor
    ) -> torch.Tensor:
        """``hidden`` (B, N, D), ``positions`` (B, N, 2), ``neighbours`` (B, N) -> pooled (B, N, out_dim)."""
        weights = cell_weights(
            positions, neighbours, cell_side=self.cell_side, grid_size=self.grid_size, soft=self.soft
        )
        values = self.hidden_encoding(hidden)  # (B, N, F)
        grid = torch.einsum("bijc,bjf->bicf", weights, values)  # flattened index c * F + f
        return torch.relu(self.embedding(grid.reshape(*grid.shape[:2], -1)))


def pooling_for(config: Any) -> tuple[GridPooling | None, int]:
    """The social pooling a net's config asks for (its ``pooling``, ``hidden_dim``, ``latent_dim``,
    ``pool_dim``, ``cell_side``, ``grid_size``) and the width it adds to the step's input; ``(None, 0)`` for
    ``pooling="none"``."""
    if config.pooling == "none":
        return None, 0
    pool = GridPooling(
        hidden_dim=config.hidden_dim,
        latent_dim=config.latent_dim,
        out_dim=config.pool_dim,
        cell_side=config.cell_side,
        grid_size=config.grid_size,
        soft=config.pooling == "soft",
    )
    return pool, config.pool_dim
