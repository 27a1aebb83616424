"""Each CasADi layer against its torch module, and the pooling grid against hand-computed cells."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import torch

from predictors.nets.pooling import cell_weights
from tests.predictors.handwritten import layers as cl


def numpy_params(module: torch.nn.Module) -> dict[str, np.ndarray]:
    return {k: v.detach().double().numpy() for k, v in module.state_dict().items()}


def test_linear_matches_torch_on_columns():
    torch.manual_seed(0)
    layer = torch.nn.Linear(3, 4).double()
    x = np.random.default_rng(0).normal(size=(5, 3))  # 5 agents
    p = numpy_params(layer)
    symbolic = np.asarray(cl.linear(ca.DM(x.T), p["weight"], p["bias"]))
    np.testing.assert_allclose(symbolic, layer(torch.from_numpy(x)).detach().numpy().T, rtol=0, atol=1e-12)


def test_linear_rejects_a_mismatched_input():
    with pytest.raises(ValueError, match=r"weight of shape \(4, 3\) cannot multiply an input of 2 rows"):
        cl.linear(ca.DM.ones(2, 1), np.ones((4, 3)))


def test_activations_hand_computed():
    x = ca.DM([-2.0, 0.0, 3.0])
    np.testing.assert_allclose(np.asarray(cl.relu(x)).ravel(), [0.0, 0.0, 3.0])
    np.testing.assert_allclose(np.asarray(cl.sigmoid(x)).ravel(), 1 / (1 + np.exp([2.0, 0.0, -3.0])))
    assert float(cl.sigmoid(ca.DM(-1000.0))) == 0.0  # exp overflow gives the right limit, not NaN


def test_lstm_cell_matches_torch():
    torch.manual_seed(1)
    cell = torch.nn.LSTMCell(6, 5).double()
    rng = np.random.default_rng(1)
    x, h, c = rng.normal(size=(3, 6)), rng.normal(size=(3, 5)), rng.normal(size=(3, 5))
    h_ref, c_ref = cell(torch.from_numpy(x), (torch.from_numpy(h), torch.from_numpy(c)))
    p = numpy_params(cell)
    h_new, c_new = cl.lstm_cell(
        ca.DM(x.T), ca.DM(h.T), ca.DM(c.T), p["weight_ih"], p["weight_hh"], p["bias_ih"], p["bias_hh"]
    )
    np.testing.assert_allclose(np.asarray(h_new), h_ref.detach().numpy().T, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(c_new), c_ref.detach().numpy().T, rtol=0, atol=1e-12)


def test_lstm_cell_with_zero_trailing_inputs_dropped():
    """The start-tag slots are zero at prediction steps: their weight columns can be left out."""
    torch.manual_seed(2)
    cell = torch.nn.LSTMCell(4, 3).double()
    x = np.array([[0.3, -0.2, 0.0, 0.0]])
    h_ref, _ = cell(torch.from_numpy(x))
    p = numpy_params(cell)
    h_new, _ = cl.lstm_cell(
        ca.DM(x[:, :2].T),
        ca.DM.zeros(3, 1),
        ca.DM.zeros(3, 1),
        p["weight_ih"][:, :2],
        p["weight_hh"],
        p["bias_ih"],
        p["bias_hh"],
    )
    np.testing.assert_allclose(np.asarray(h_new), h_ref.detach().numpy().T, rtol=0, atol=1e-12)


# Grid of 6 x 6 cells of 0.8 m: u = (p_j - p_i) / 0.8 + 3; cell centres at u = k + 0.5.
GRID = {"cell_side": 0.8, "grid_size": 6}


def casadi_weights(positions: np.ndarray, soft: bool, present=None) -> np.ndarray:
    """(N * C, N) -> (N, N, C) like the torch version."""
    n = positions.shape[0]
    present = np.ones((1, n)) if present is None else np.asarray(present, dtype=float)[None]
    w = np.asarray(
        cl.grid_cell_weights(ca.DM(positions.T), soft=soft, neighbour_weight=ca.DM(present), **GRID)
    )
    return w.reshape(n, 36, n).transpose(0, 2, 1)


def test_hard_cell_hand_computed():
    # neighbour at (+0.5, -0.3): u = (3.625, 2.625) -> cell kx=3, ky=2 -> c = 3 * 6 + 2 = 20 of agent 0;
    # agent 1 sees agent 0 at u = (2.375, 3.375) -> kx=2, ky=3 -> c = 15.
    positions = np.array([[0.0, 0.0], [0.5, -0.3]])
    w = casadi_weights(positions, soft=False)
    assert w[0, 1].nonzero()[0].tolist() == [20] and w[0, 1, 20] == 1.0
    assert w[1, 0].nonzero()[0].tolist() == [15]
    assert not w[0, 0].any() and not w[1, 1].any()  # never its own neighbour


def test_soft_cell_weights_hand_computed():
    # u = (3.625, 2.625): along x the tents centred at 3.5 and 4.5 give 0.875 and 0.125, along y the tents
    # at 2.5 and 3.5 give 0.875 and 0.125; the cell weight is their product.
    positions = np.array([[0.0, 0.0], [0.5, -0.3]])
    w = casadi_weights(positions, soft=True)[0, 1]
    expected = {
        3 * 6 + 2: 0.875 * 0.875,
        3 * 6 + 3: 0.875 * 0.125,
        4 * 6 + 2: 0.125 * 0.875,
        4 * 6 + 3: 0.125 * 0.125,
    }
    assert sorted(w.nonzero()[0].tolist()) == sorted(expected)
    for cell, value in expected.items():
        assert w[cell] == pytest.approx(value, abs=1e-12)
    assert w.sum() == pytest.approx(1.0)


def test_out_of_range_and_absent_neighbours_are_not_pooled():
    # 2.9 m away is beyond the hard grid's +-2.4 m and the soft grid's +-2.8 m (its outer tents reach half a
    # cell further); the third agent is close but absent.
    positions = np.array([[0.0, 0.0], [2.9, 0.0], [0.2, 0.2]])
    for soft in (False, True):
        w = casadi_weights(positions, soft=soft, present=[1, 1, 0])
        assert not w[0, 1].any() and not w[0, 2].any()


@pytest.mark.parametrize("soft", [False, True])
def test_torch_and_casadi_cell_weights_agree(soft):
    rng = np.random.default_rng(3)
    positions = rng.uniform(-2.0, 2.0, (7, 2))
    present = rng.random(7) < 0.8
    ref = cell_weights(torch.from_numpy(positions)[None], torch.from_numpy(present)[None], soft=soft, **GRID)
    np.testing.assert_array_equal(casadi_weights(positions, soft, present), ref[0].numpy())


def test_grid_pool_sums_values_into_cells():
    positions = np.array([[0.0, 0.0], [0.5, -0.3], [0.52, -0.31]])  # agents 1 and 2 share agent 0's cell 20
    values = np.array([[1.0, 10.0, 100.0], [2.0, 20.0, 200.0]])  # (F=2, N=3)
    w = cl.grid_cell_weights(ca.DM(positions.T), soft=False, neighbour_weight=ca.DM.ones(1, 3), **GRID)
    grid = np.asarray(cl.grid_pool(ca.DM(values), w))  # (C * F, N), row c * F + f
    assert grid.shape == (72, 3)
    np.testing.assert_allclose(grid[40:42, 0], [110.0, 220.0])  # cell 20 of agent 0: agents 1 + 2
    assert np.count_nonzero(grid[:, 0]) == 2


def test_soft_weights_have_a_gradient_and_hard_do_not():
    p = ca.MX.sym("p", 2, 2)
    for soft, nonzero in ((True, True), (False, False)):
        w = cl.grid_cell_weights(p, soft=soft, neighbour_weight=ca.DM.ones(1, 2), **GRID)
        jac = ca.Function("weights_jacobian", [p], [ca.jacobian(ca.vec(w), ca.vec(p))])
        value = np.asarray(jac(np.array([[0.0, 0.5], [0.0, -0.3]])))
        assert bool(np.abs(value).max() > 0) is nonzero
