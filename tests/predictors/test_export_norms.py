"""The 2-norm's torch names (torch.norm, Tensor.norm, torch.linalg.norm / vector_norm, F.normalize) exported
against torch to 1e-9 in values and Jacobians, at 0 too, where torch's gradient is 0 and sqrt's is inf.

`crowdmpc export` of a user's net computing its neighbours' distances with torch.norm was refused
("unsupported operation torch.norm"), and the same distances written as sqrt((d ** 2).sum(-1)) were refused
for NaN Jacobians (an agent's distance to itself is 0): torch.norm trains with a finite gradient there.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import torch
import torch.nn.functional as F

from predictors.export import ExportError, TensorSpec, export_function
from tests.predictors.test_export import Wrap


def _pairs(x):  # (N, 2) positions -> (N, N, 2) relative positions, their diagonal exactly 0
    return x[None, :, :] - x[:, None, :]


NORMS = {
    "torch_norm": lambda m, x: torch.norm(_pairs(x), dim=-1),
    "tensor_norm_keepdim": lambda m, x: _pairs(x).norm(2, -1, keepdim=True) * 2,
    "linalg_norm": lambda m, x: torch.linalg.norm(_pairs(x), dim=-1) + torch.linalg.norm(x),
    "linalg_vector_norm": lambda m, x: torch.linalg.vector_norm(_pairs(x), dim=(1, 2)),
    "flattened": lambda m, x: torch.norm(_pairs(x)) + x.norm(),
    "normalize": lambda m, x: F.normalize(_pairs(x), dim=-1),
    "zero_rows": lambda m, x: torch.norm(x * torch.tensor([[0.0], [1.0], [0.0]], dtype=x.dtype), dim=1),
    # row 0 is at the point: a norm of 0 whose input moves with x, where torch's gradient is 0
    "at_a_point": lambda m, x: torch.linalg.vector_norm(
        x - torch.tensor([[0.3, -1.2]], dtype=x.dtype), dim=1
    ),
}


def _positions():
    return torch.tensor([[0.3, -1.2], [2.0, 0.5], [-0.7, 0.9]], dtype=torch.float64)


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("name", sorted(NORMS))
def test_a_norm_matches_torch_in_values_and_jacobians_at_zero_too(name, symbol):
    module = Wrap(NORMS[name]).double().eval()
    x = _positions()
    function = export_function(module, module.forward, [TensorSpec("x", (3, 2))], ["y"], "f", symbol=symbol)
    with torch.no_grad():
        expected = module(x).reshape(-1).numpy()
    np.testing.assert_allclose(np.asarray(function(x.numpy().ravel())).ravel(), expected, rtol=0, atol=1e-9)
    a = ca.MX.sym("a", 6)
    jacobian = ca.Function("j", [a], [ca.jacobian(function(a), a)])
    got = np.asarray(jacobian(x.numpy().ravel()))
    torch_jac = torch.autograd.functional.jacobian(lambda y: module(y).reshape(-1), x).reshape(got.shape)
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, torch_jac.numpy(), rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    ("fn", "message"),
    [
        (
            lambda m, x: torch.norm(x, p=1, dim=-1),
            r"torch\.norm of order 1 \(the export maps the 2-norm only\)",
        ),
        # a matrix's ord=2 is its spectral norm
        (lambda m, x: torch.linalg.norm(x, ord=2), r"torch\.linalg\.norm of order 2"),
        (lambda m, x: torch.linalg.vector_norm(x, ord=float("inf")), r"vector_norm of order inf"),
    ],
    ids=["l1", "spectral", "max"],
)
def test_a_norm_of_another_order_is_refused_in_one_line(fn, message):
    module = Wrap(fn).double()
    with pytest.raises(ExportError, match=message) as info:
        export_function(module, module.forward, [TensorSpec("x", (3, 2))], ["y"], "f")
    assert "\n" not in str(info.value)
