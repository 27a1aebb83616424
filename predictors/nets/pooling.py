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

The sum is computed one of two ways, with the same weights bit for bit (only the order of the additions
differs), chosen by ``GridPooling.forward`` with ``uses_sparse_pooling``:

* dense (``dense_grid_pool``: ``cell_weights`` and an einsum): a ``(B, N, N, grid_size**2)`` weight tensor,
  ``B·N²·C`` time and memory at every step, kept for the backward pass. ``predictors.export`` traces this one.
* sparse (``sparse_grid_pool``): the pairs inside the grid are found first, then each pair's value is added
  into its cell (hard) or its four nearest cells (soft) with ``index_put(accumulate=True)``; only finding
  the pairs looks at all ``B·N²`` of them. Which pairs those are depends on the positions' values, which the
  exporter's symbolic tensors do not have, so it runs only on plain torch tensors: training, evaluation and
  the torch rollout. A Social-LSTM training step (8 scenes of 320 agents, one thread) took 11.4 s and 2.8 GB
  dense, 0.54 s and 0.44 GB sparse (``benchmarks/pooling.py``).

``predictors.export`` exports the dense code as it is; the hand-written twin kept as a cross-check,
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


def dense_grid_pool(
    values: torch.Tensor,
    positions: torch.Tensor,
    neighbours: torch.Tensor,
    *,
    cell_side: float,
    grid_size: int,
    soft: bool,
) -> torch.Tensor:
    """``values`` (B, N, F) of the neighbours summed per cell of each agent's grid, weighted by
    ``cell_weights``: (B, N, C, F). The form ``predictors.export`` traces."""
    weights = cell_weights(positions, neighbours, cell_side=cell_side, grid_size=grid_size, soft=soft)
    return torch.einsum("bijc,bjf->bicf", weights, values)


def uses_sparse_pooling(*tensors: Any) -> bool:
    """Whether ``GridPooling`` may take the sparse path: every input is a plain ``torch.Tensor`` and torch is
    not tracing or compiling.

    The sparse path indexes with the pairs it finds in the positions' values. ``predictors.export`` runs the
    net on its ``SymTensor`` (not a ``torch.Tensor``), and ``torch.fx`` on a ``Proxy``: neither has values,
    so the export always takes the dense path. A tensor subclass (a ``FakeTensor`` of ``torch.compile``, any
    other ``__torch_function__`` tracer) and ``torch.jit.trace``, which would record the example's pairs as
    constants, take it too. The test is on the inputs' types, not on a flag someone must remember to set.
    """
    if torch.jit.is_tracing() or torch.compiler.is_compiling():
        return False
    return all(type(t) is torch.Tensor for t in tensors)


def _pairs_in_range(
    positions: torch.Tensor, neighbours: torch.Tensor, *, cell_side: float, grid_size: int, soft: bool
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(b, i, j)`` of every pair with a weight in some cell of ``cell_weights`` that may be non-zero: ``j``
    a neighbour other than ``i`` whose ``u`` is in ``[0, grid_size)`` on both axes (hard) or in ``(-0.5,
    grid_size + 0.5)`` (soft: an outer cell's tent reaches half a cell beyond the edge, where it is 0 with a
    zero slope, so a pair on that bound adds nothing to the values or the gradients).

    The step that looks at all pairs: (B, N, N, 2) relative coordinates and (B, N, N) masks, without
    gradient; nothing of size ``N²·C`` is built.
    """
    n_agents = positions.shape[1]
    with torch.no_grad():
        u = (positions[:, None, :, :] - positions[:, :, None, :]) / cell_side + grid_size / 2
        low, high = (-0.5, grid_size + 0.5) if soft else (0.0, float(grid_size))
        inside = (u > low) & (u < high) if soft else (u >= low) & (u < high)
        pooled = inside[..., 0] & inside[..., 1] & (neighbours != 0)[:, None, :]
        pooled &= ~torch.eye(n_agents, dtype=torch.bool, device=positions.device)
    b, i, j = pooled.nonzero(as_tuple=True)
    return b, i, j


def _corners(u: torch.Tensor, grid_size: int, soft: bool) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per pair (``u`` (P, 2)) its cells, their weights before the neighbour mask and which cells are on the
    grid: ``(P, K)`` each, K = 1 (hard) or 4 (soft), the weights as ``cell_weights`` computes them.

    Soft: per axis the two cell centres ``k + 0.5`` nearest ``u`` (``k = floor(u) - 1`` below the middle of a
    cell, ``floor(u)`` above; ``u - floor(u)`` is exact in floating point), the only ones within 1 of ``u``.
    """
    with torch.no_grad():
        k = torch.floor(u)
        if soft:
            low = k - (u - k < 0.5).to(u.dtype)
            k = torch.stack([low, low + 1], dim=-1)  # (P, 2 axes, 2 centres)
        else:
            k = k[..., None]  # (P, 2 axes, 1)
        on_grid = (k >= 0) & (k < grid_size)
        k_int = k.long()
    if soft:
        per_axis = torch.relu(1 - torch.abs(u[..., None] - (k + 0.5)))
    else:
        per_axis = torch.ones_like(k)  # u is in the cell: (u >= k) & (u < k + 1) is 1
    weights = per_axis[:, 0, :, None] * per_axis[:, 1, None, :]  # (P, n, n), x then y as cell_weights
    cells = k_int[:, 0, :, None] * grid_size + k_int[:, 1, None, :]
    inside = on_grid[:, 0, :, None] & on_grid[:, 1, None, :]
    return cells.flatten(1), weights.flatten(1), inside.flatten(1)


def sparse_grid_pool(
    values: torch.Tensor,
    positions: torch.Tensor,
    neighbours: torch.Tensor,
    *,
    cell_side: float,
    grid_size: int,
    soft: bool,
) -> torch.Tensor:
    """``dense_grid_pool`` from the pairs inside the grid only: the same weights bit for bit, each pair's
    ``weight * value`` added into its cell with ``index_put(accumulate=True)``; the sums' order differs.

    Plain torch tensors only (``uses_sparse_pooling``). Memory beyond ``_pairs_in_range``'s (B, N, N) masks is
    per pair in range: a few floats and the pair's ``K`` weighted values of width F.
    """
    batch, n_agents, width = values.shape
    n_cells = grid_size * grid_size
    b, i, j = _pairs_in_range(positions, neighbours, cell_side=cell_side, grid_size=grid_size, soft=soft)
    # u[b, i, j] of cell_weights, with the same operations (the same values bit for bit), for these pairs
    u = (positions[b, j] - positions[b, i]) / cell_side + grid_size / 2  # (P, 2)
    cells, weights, inside = _corners(u, grid_size, soft)
    weights = weights * neighbours.to(positions.dtype)[b, j][:, None]  # cell_weights' column, j != i
    row = ((b * n_agents + i) * n_cells)[:, None] + cells  # (P, K) rows of the (B·N·C, F) output
    pair = torch.arange(len(b), device=values.device)[:, None].expand_as(cells)
    row, pair, weights = row[inside], pair[inside], weights[inside]
    grid = values.new_zeros(batch * n_agents * n_cells, width)
    # in values' dtype: under autocast (bf16-mixed) they are bfloat16 and the weights float32; a no-op else
    shares = (weights[:, None] * values[b[pair], j[pair]]).to(grid.dtype)
    return grid.index_put((row,), shares, accumulate=True).reshape(batch, n_agents, n_cells, width)


class GridPooling(nn.Module):
    """Neighbours' hidden states, compressed to ``latent_dim``, summed per cell, then ``Linear + ReLU``.

    ``sparse`` (default True): plain torch tensors take the sparse path (``uses_sparse_pooling``); False
    keeps every call on the dense one, the one the export traces (the parity tests, benchmarks/pooling.py).
    """

    sparse: bool = True

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
        values = self.hidden_encoding(hidden)  # (B, N, F)
        sparse = self.sparse and uses_sparse_pooling(values, positions, neighbours)
        pool = sparse_grid_pool if sparse else dense_grid_pool
        grid = pool(
            values, positions, neighbours, cell_side=self.cell_side, grid_size=self.grid_size, soft=self.soft
        )
        return torch.relu(self.embedding(grid.reshape(*grid.shape[:2], -1)))  # flattened index c * F + f


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
