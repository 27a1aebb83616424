"""NaN through the exported activations and 2-norms: NaN where torch gives NaN, the other entries as torch's.

CasADi's comparisons are false for NaN, and the export's if_else forms of relu, clamp and sigmoid sent a
NaN to their constant branch: relu(nan) was 0, clamp(nan, 0, 2) was 0, sigmoid(nan) was 1.2e-308 (its floor),
where torch's are NaN, so an exported net fed a NaN (a missing position) gave numbers. The 2-norm (torch.norm,
F.normalize, torch.cdist) of a NaN was 0, its sqrt taken only where the sum of squares is > 0. The extremes'
NaN (amax, torch.max ...) is tested in test_export_extremes.py.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
import torch
import torch.nn.functional as F

from predictors.export import TensorSpec, export_function
from tests.predictors.test_export import Wrap

NAN = math.nan
# NaN first, between, last, beside entries on either side of every branch point (0, the sigmoid's floor)
POINT = [[NAN, -1.5, 0.0, 0.4], [2.5, NAN, -800.0, 1.0], [-0.3, 3.0, 0.7, NAN]]
BOUNDS = [[0.0, NAN, 0.5, 0.0], [1.0, 0.0, 0.0, NAN], [NAN, 0.0, 1.0, 0.0]]

CASES = {
    "relu": lambda m, x, y: torch.relu(x) + 2 * F.relu(x) + 3 * x.relu(),
    "clamp_scalar_bounds": lambda m, x, y: (
        x.clamp(0.0, 2.0) + 2 * torch.clip(x, min=-1.0) + 3 * x.clamp(max=0.5)
    ),
    "clamp_tensor_bounds": lambda m, x, y: torch.clamp(x, min=y) + 2 * torch.clamp(x, max=y),
    "clamp_nan_bound": lambda m, x, y: torch.stack(
        [x[0].clamp(min=NAN), y[1].clamp(max=torch.tensor(NAN)), x[2].clamp(min=0.0)]
    ),
    "sigmoid": lambda m, x, y: torch.sigmoid(x) + 2 * F.sigmoid(-x),
    "norms": lambda m, x, y: torch.cat(
        [torch.norm(x, dim=1, keepdim=True), x[:, :2].norm(dim=0)[None].expand(3, 2), F.normalize(x, dim=0)],
        1,
    ),
    "cdist": lambda m, x, y: torch.cdist(x[:, :2], y[:, :2]),
}


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_nan_stays_nan_as_in_torch(name, symbol):
    module = Wrap(CASES[name]).double()
    inputs = [torch.tensor(p, dtype=torch.float64) for p in (POINT, BOUNDS)]
    specs = [TensorSpec(n, (3, 4)) for n in ("x", "y")]
    function = export_function(module, module.forward, specs, ["z"], "f", symbol=symbol)
    with torch.no_grad():
        expected = module(*inputs).reshape(-1).numpy()
    got = np.asarray(function(*(x.numpy().ravel() for x in inputs))).ravel()
    assert np.isnan(expected).any() and not np.isnan(expected).all()
    np.testing.assert_array_equal(np.isnan(got), np.isnan(expected))
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
