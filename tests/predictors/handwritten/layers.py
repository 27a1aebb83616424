"""CasADi twins of the torch layers the learned predictors are built from (like l4casadi's naive layers).

Every function takes the layer's weights as float64 numpy arrays (as torch stores them: ``weight`` is
``(out, in)``) and CasADi expressions, and returns the same map as the torch module, symbolically. Agents are
**columns**: a layer maps a ``(features, N)`` matrix to ``(out, N)``, so one dense ``mtimes`` serves every
agent at once and an MX graph stays a few hundred nodes per step instead of one node per scalar.

This module imports neither torch nor anything of the project: written apart from the exporter
(``predictors.export``), it checks it. The torch side of every piece lives in ``predictors.nets``;
``tests/predictors/test_casadi_layers.py`` checks each pair.
"""

from __future__ import annotations

from typing import TypeAlias

import casadi as ca
import numpy as np

# CasADi is checked as untyped (see pyproject.toml), so this alias is Any to mypy; it documents intent.
Expr: TypeAlias = ca.MX | ca.SX | ca.DM


def _bias_columns(bias: np.ndarray, n_cols: int) -> ca.DM:
    return ca.repmat(ca.DM(np.asarray(bias, dtype=np.float64).reshape(-1, 1)), 1, n_cols)


# ----------------------------------------------------------------------------------------------- activations
def relu(x: Expr) -> Expr:
    return ca.fmax(x, 0)


def sigmoid(x: Expr) -> Expr:
    # exp(-x) overflows to inf for x << 0, and 1 / (1 + inf) is the correct limit 0.
    return 1 / (1 + ca.exp(-x))


def tanh(x: Expr) -> Expr:
    return ca.tanh(x)


# ------------------------------------------------------------------------------------------------ layers
def linear(x: Expr, weight: np.ndarray, bias: np.ndarray | None = None) -> Expr:
    """``torch.nn.Linear``: ``weight`` (out, in), ``bias`` (out,); ``x`` (in, N) -> (out, N)."""
    weight = np.asarray(weight, dtype=np.float64)
    if weight.ndim != 2 or weight.shape[1] != x.shape[0]:
        raise ValueError(
            f"linear: weight of shape {weight.shape} cannot multiply an input of {x.shape[0]} rows"
        )
    y = ca.mtimes(ca.DM(weight), x)
    if bias is not None:
        y = y + _bias_columns(bias, x.shape[1])
    return y


def lstm_cell(
    x: Expr,
    h: Expr,
    c: Expr,
    weight_ih: np.ndarray,
    weight_hh: np.ndarray,
    bias_ih: np.ndarray,
    bias_hh: np.ndarray,
) -> tuple[Expr, Expr]:
    """``torch.nn.LSTMCell`` (gate order i, f, g, o): ``x`` (in, N), ``h``/``c`` (D, N) -> new ``(h, c)``.

    ``weight_ih`` may have fewer columns than torch's when trailing inputs are known to be zero (the
    TrajNet++ start tags): pass ``weight_ih[:, :rows_of_x]``.
    """
    hidden = np.asarray(weight_hh).shape[1]
    gates = linear(x, weight_ih) + linear(h, weight_hh, np.asarray(bias_ih) + np.asarray(bias_hh))
    i = sigmoid(gates[0:hidden, :])
    f = sigmoid(gates[hidden : 2 * hidden, :])
    g = tanh(gates[2 * hidden : 3 * hidden, :])
    o = sigmoid(gates[3 * hidden : 4 * hidden, :])
    c_new = f * c + i * g
    return o * tanh(c_new), c_new


# ----------------------------------------------------------------------------------------------- pooling
def grid_cell_weights(
    positions: Expr, *, cell_side: float, grid_size: int, soft: bool, neighbour_weight: Expr
) -> Expr:
    """Weight of neighbour ``j`` in cell ``c`` of agent ``i``'s grid: ``(N * C, N)``, row ``i * C + c``.

    ``positions`` is ``(2, N)``; the grid is ``grid_size x grid_size`` cells (``C = grid_size**2``) of
    ``cell_side`` metres centred on each agent and aligned with the world axes, cell
    ``c = kx * grid_size + ky`` (TrajNet++'s order). Hard (``soft=False``): 1 in the cell that holds the
    neighbour, by comparisons, so the derivative with respect to positions is zero. Soft: bilinear ("tent")
    weights of the neighbour over the four nearest cell centres; they sum to 1 between the outermost cell
    centres and fade linearly to 0 half a cell beyond the grid's edge, so the map is continuous and its
    derivative with respect to positions is non-zero. ``neighbour_weight`` (1, N) multiplies column ``j``
    (1 for present agents, 0 for absent ones); an agent is never its own neighbour.

    All ``N * C`` rows are built by a handful of whole-matrix operations (a row gather, constant offsets),
    not one node per cell: an MX graph with few large nodes is what keeps evaluation and AD cheap.
    """
    n_agents = positions.shape[1]
    n_cells = grid_size * grid_size
    agent_of_row = np.repeat(np.arange(n_agents), n_cells).tolist()
    kx, ky = np.divmod(np.tile(np.arange(n_cells), n_agents), grid_size)
    weights = None
    for axis, k in ((0, kx), (1, ky)):
        row = positions[axis, :]
        # u[i, j] = (p_j - p_i) / cell_side + grid_size / 2: neighbour j in agent i's cell units.
        u = (ca.repmat(row, n_agents, 1) - ca.repmat(row.T, 1, n_agents)) / cell_side + grid_size / 2
        u_rows = u[agent_of_row, :]
        if soft:
            offset = ca.DM(np.repeat((k + 0.5)[:, None], n_agents, axis=1))
            per_axis = relu(1 - ca.fabs(u_rows - offset))
        else:
            low = ca.DM(np.repeat(k[:, None].astype(float), n_agents, axis=1))
            per_axis = (u_rows >= low) * (u_rows < low + 1)
        weights = per_axis if weights is None else weights * per_axis
    off_diagonal = ca.DM(1.0 - np.eye(n_agents))
    column_weight = ca.repmat(neighbour_weight, n_agents, 1) * off_diagonal
    return weights * column_weight[agent_of_row, :]


def grid_pool(values: Expr, cell_weights: Expr) -> Expr:
    """Sum each agent's neighbours' ``values`` (F, N) into its cells: ``(C * F, N)``, row ``c * F + f``.

    ``values @ cell_weights.T`` is ``(F, N * C)`` with column ``i * C + c``; CasADi's column-major reshape
    to ``(C * F, N)`` puts entry ``(f, i * C + c)`` at row ``c * F + f`` of column ``i``.
    """
    n_agents = values.shape[1]
    n_features = values.shape[0]
    n_cells = cell_weights.shape[0] // n_agents
    return ca.reshape(ca.mtimes(values, cell_weights.T), n_cells * n_features, n_agents)
