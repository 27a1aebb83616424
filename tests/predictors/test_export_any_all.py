"""torch.any / torch.all and their methods exported against torch: masks of a mask or of numbers (nonzero is
true), over every dim, one, several, with keepdim, and used as torch code uses them, in torch.where.

A user's attention net marked the agents with nobody in view with ``blocked.all(-1, keepdim=True)``; `crowdmpc
export` refused it ("unsupported tensor method .all()"), as it refused torch.any and torch.all.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import torch

from predictors.export import TensorSpec, export_function
from tests.predictors.test_export import Wrap, check

REDUCTIONS = {
    "method_dim_keepdim": lambda m, x, k: k.all(-1, keepdim=True) * 1.0 + 2.0 * k.any(0, keepdim=True),
    "functions": lambda m, x, k: torch.any(k, 1) * 1.0 + 2.0 * torch.all(k, dim=0) * 1.0,
    "everything": lambda m, x, k: torch.stack([k.any(), k.all(), torch.any(x > 9), torch.all(x > -9)]) * 1.0,
    "several_dims": lambda m, x, k: torch.all(k[None], dim=(0, 2)) * 1.0 + x.any(dim=(1,)) * 1.0,
    "numbers": lambda m, x, k: (x * k).any(-1) * 1.0 + (x * k).all(-1) * 2.0,
    "in_where": lambda m, x, k: torch.where(k.all(-1, keepdim=True), x, -x) * x.sum(),
}


def _inputs():
    x = torch.tensor([[0.3, -1.2, 0.0], [2.0, 0.5, -0.4], [-0.7, 0.9, 1.1]], dtype=torch.float64)
    k = torch.tensor([[True, True, True], [True, False, True], [False, False, False]])
    return x, k


@pytest.mark.parametrize("name", sorted(REDUCTIONS))
def test_any_and_all_match_torch(name):
    x, k = _inputs()
    if name == "in_where":
        check(Wrap(REDUCTIONS[name]), x, k, atol=1e-12)  # values and the Jacobian against torch
        return
    module = Wrap(REDUCTIONS[name]).double()
    specs = [TensorSpec("x", (3, 3)), TensorSpec("k", (3, 3), True)]
    for symbol in (ca.MX, ca.SX):
        function = export_function(module, module.forward, specs, ["y"], "f", symbol=symbol)
        got = np.asarray(function(x.numpy().ravel(), k.numpy().ravel().astype(float))).ravel()
        np.testing.assert_array_equal(got, module(x, k).reshape(-1).numpy())
