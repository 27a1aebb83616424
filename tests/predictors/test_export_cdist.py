"""torch.cdist (p = 2) exported against torch to 1e-9 in values and Jacobians, batched, and at a distance of
0 (an agent's to itself), where torch's gradient is 0 and sqrt's is inf.

`crowdmpc export` of a user's net taking its agents' pairwise distances with torch.cdist was refused
("unsupported operation torch.cdist"): pedestrian predictors commonly do.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import torch

from predictors.export import ExportError, TensorSpec, export_function
from tests.predictors.test_export import Wrap


def _point(x):
    return torch.tensor([[0.3, -1.2]], dtype=x.dtype)


CDISTS = {
    # (3, 2) with itself: the diagonal, each agent's distance to itself, is 0
    "self": lambda m, x: torch.cdist(x, x),
    "two_sets": lambda m, x: torch.cdist(x, 2.0 * x[:2] + 1.0, p=2),
    # (2, 3, 2) and (3, 2): the batch dim broadcast
    "batched": lambda m, x: torch.cdist(torch.stack([x, x * x]), x),
    # (2, 1, 3, 2) and (3, 3, 2) -> (2, 3, 3, 3)
    "broadcast_batches": lambda m, x: torch.cdist(
        torch.stack([x, x + 1.0]).unsqueeze(1), torch.stack([x, -x, 0.5 * x[[2, 0, 1]]])
    ),
    # x's row 0 against itself, both moving with x, and against a fixed point it sits at
    "zero_between_two_inputs": lambda m, x: torch.cdist(x, x[:1]) + torch.cdist(x, _point(x)),
    "compute_mode": lambda m, x: torch.cdist(x, x, compute_mode="donot_use_mm_for_euclid_dist"),
}


def _positions():
    return torch.tensor([[0.3, -1.2], [2.0, 0.5], [-0.7, 0.9]], dtype=torch.float64)


def _export_and_compare(fn, x, symbol, value_atol=1e-9):
    module = Wrap(fn).double().eval()
    spec = [TensorSpec("x", tuple(x.shape))]
    function = export_function(module, module.forward, spec, ["y"], "f", symbol=symbol)
    with torch.no_grad():
        expected = module(x).reshape(-1).numpy()
    got_values = np.asarray(function(x.numpy().ravel())).ravel()
    np.testing.assert_allclose(got_values, expected, rtol=0, atol=value_atol)
    a = ca.MX.sym("a", x.numel())
    jacobian = ca.Function("j", [a], [ca.jacobian(function(a), a)])
    got = np.asarray(jacobian(x.numpy().ravel()))
    torch_jac = torch.autograd.functional.jacobian(lambda y: module(y).reshape(-1), x).reshape(got.shape)
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, torch_jac.numpy(), rtol=0, atol=1e-9)


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("name", sorted(CDISTS))
def test_cdist_matches_torch_in_values_and_jacobians_at_zero_too(name, symbol):
    _export_and_compare(CDISTS[name], _positions(), symbol)


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
def test_cdist_of_more_than_25_agents_matches_torch_which_takes_it_from_a_matmul(symbol):
    """Past 25 rows torch's default computes the distances from a matmul, off by rounding (1.5e-8 at 0 in
    float64); its gradient is still 0 at 0, as the export's."""
    x = torch.randn(30, 2, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    _export_and_compare(lambda m, y: torch.cdist(y, y), x, symbol, value_atol=1e-7)


@pytest.mark.parametrize(
    ("fn", "message"),
    [
        (
            lambda m, x: torch.cdist(x, x, p=1.0),
            r"torch\.cdist of order 1\.0 \(the export maps the 2-norm only\)",
        ),
        (lambda m, x: torch.cdist(x, x, p=float("inf")), r"torch\.cdist of order inf"),
        (lambda m, x: torch.cdist(x, x[:, :1]), r"torch\.cdist of shapes \(3, 2\) and \(3, 1\)"),
        (lambda m, x: torch.cdist(x, x, compute_mode="fast"), r"torch\.cdist compute_mode 'fast' \(one of"),
    ],
    ids=["l1", "max", "columns_differ", "compute_mode"],
)
def test_cdist_of_another_order_or_shapes_that_do_not_pair_is_refused_in_one_line(fn, message):
    module = Wrap(fn).double()
    with pytest.raises(ExportError, match=message) as info:
        export_function(module, module.forward, [TensorSpec("x", (3, 2))], ["y"], "f")
    assert "\n" not in str(info.value)
