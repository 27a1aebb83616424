"""torch.amax / torch.amin and their methods exported against torch to 1e-9 in values and Jacobians: over
every dim, one, several, with keepdim, with ties (torch shares the gradient evenly among equal entries) and
with -inf entries (a masked neighbour).

A user's net max-pooling its neighbours' features, `torch.where(valid, feats, -1e4).amax(dim=2)`, was refused
by `crowdmpc export` ("unsupported tensor method .amax()").
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
import torch

from predictors.export import TensorSpec, export_function
from tests.predictors.test_export import Wrap

INF = math.inf
EXTREMES = {
    "method_dim": lambda m, x: x.amax(dim=-1) + 2 * x.amin(dim=0),
    "keepdim": lambda m, x: x.amax(1, keepdim=True) * x,
    "functions_every_dim": lambda m, x: torch.amax(x) + 2 * torch.amin(x, dim=()),
    "several_dims": lambda m, x: torch.amax(x[None] * 2, dim=(0, 2)) + torch.amin(x[:, None], (1, 2)),
    "masked": lambda m, x: torch.where(x > 0, x, torch.full_like(x, -INF)).amax(-1),
    "max_pool": lambda m, x: torch.amax(torch.where(x > 0, x**2, -1e4), dim=0),
}
POINTS = {
    "distinct": [[0.3, -1.2, 0.4], [2.0, 0.5, -0.4], [-0.7, 0.9, 1.1]],
    "ties": [[1.5, 1.5, 1.5], [2.0, -0.5, 2.0], [-0.7, -0.7, 1.1]],  # three-way, two-way, at the minimum
}


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("point", sorted(POINTS))
@pytest.mark.parametrize("name", sorted(EXTREMES))
def test_amax_and_amin_match_torch_in_values_and_jacobians(name, point, symbol):
    module = Wrap(EXTREMES[name]).double()
    x = torch.tensor(POINTS[point], dtype=torch.float64)
    function = export_function(module, module.forward, [TensorSpec("x", (3, 3))], ["y"], "f", symbol=symbol)
    with torch.no_grad():
        expected = module(x).reshape(-1).numpy()
    np.testing.assert_allclose(np.asarray(function(x.numpy().ravel())).ravel(), expected, rtol=0, atol=1e-9)
    a = ca.MX.sym("a", 9)
    got = np.asarray(ca.Function("j", [a], [ca.jacobian(function(a), a)])(x.numpy().ravel()))
    torch_jac = torch.autograd.functional.jacobian(lambda y: module(y).reshape(-1), x).reshape(got.shape)
    np.testing.assert_allclose(got, torch_jac.numpy(), rtol=0, atol=1e-9)
