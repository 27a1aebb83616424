"""torch.amax / torch.amin, torch.max / torch.min and their methods exported against torch to 1e-9 in values
and Jacobians: over every dim, one, several, with keepdim, with ties (torch shares amax's gradient evenly
among equal entries, and gives max(dim)'s to the first) and with -inf entries (a masked neighbour); the
indices of max(dim), which cannot be exported, refused where they are used.

A user's net max-pooling its neighbours' features, `torch.where(valid, feats, -1e4).amax(dim=2)`, was refused
by `crowdmpc export` ("unsupported tensor method .amax()").
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
import torch
import torch.nn.functional as F

from predictors.export import ExportError, TensorSpec, export_function
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
    _assert_matches_torch(EXTREMES[name], POINTS[point], symbol)


def _assert_matches_torch(fn, point, symbol) -> None:
    """The export of ``fn`` of a 3 x 3 input against torch at ``point``: values, and the Jacobian against
    torch's autograd (where ties decide which entry the gradient goes to)."""
    module = Wrap(fn).double()
    x = torch.tensor(point, dtype=torch.float64)
    function = export_function(module, module.forward, [TensorSpec("x", (3, 3))], ["y"], "f", symbol=symbol)
    with torch.no_grad():
        expected = module(x).reshape(-1).numpy()
    np.testing.assert_allclose(np.asarray(function(x.numpy().ravel())).ravel(), expected, rtol=0, atol=1e-9)
    a = ca.MX.sym("a", 9)
    got = np.asarray(ca.Function("j", [a], [ca.jacobian(function(a), a)])(x.numpy().ravel()))
    torch_jac = torch.autograd.functional.jacobian(lambda y: module(y).reshape(-1), x).reshape(got.shape)
    np.testing.assert_allclose(got, torch_jac.numpy(), rtol=0, atol=1e-9)


# torch.max / torch.min and their methods in each of torch's forms. Over a dim torch's gradient goes to the
# first extreme entry (the index it returns), where amax's is shared among ties: the "ties" point tells them
# apart. `x.max(dim)` was refused ("unsupported tensor method .max()"), and the guide said to write amax.
MAX_MIN = {
    "method_values": lambda m, x: x.max(dim=1).values + 2 * x.min(0).values,
    "function_keepdim": lambda m, x: (
        torch.max(x, 1, keepdim=True)[0] * x + torch.min(x, dim=0, keepdim=True)[0]
    ),
    "unpacked": lambda m, x: _values_only(*torch.max(x, -1)) + 2 * _values_only(*x.min(-2)),
    "every_entry": lambda m, x: torch.max(x) + 2 * x.min() + x,
    "elementwise": lambda m, x: torch.max(x, x.T) + 2 * torch.min(x, other=0.5 * x) + 4 * x.max(x * x),
    "masked": lambda m, x: torch.where(x > 0, x, torch.full_like(x, -INF)).max(-1).values,
    "of_a_mask": lambda m, x: (x > 0.45).max(1).values * x[:, 0] + (x > 0.45).min(dim=1)[0] * x[:, 1],
}
POINTS_AND_RANDOM = POINTS | {
    "random": torch.randn(3, 3, generator=torch.Generator().manual_seed(0)).tolist()
}


def _values_only(values, indices):
    return values


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("point", sorted(POINTS_AND_RANDOM))
@pytest.mark.parametrize("name", sorted(MAX_MIN))
def test_max_and_min_values_match_torch_in_values_and_jacobians(name, point, symbol):
    _assert_matches_torch(MAX_MIN[name], POINTS_AND_RANDOM[point], symbol)


INDICES = "indices cannot be exported, only values: use"


@pytest.mark.parametrize(
    ("fn", "message"),
    [
        (lambda m, x: torch.gather(x, 1, x.max(1, keepdim=True).indices), "x.max(dim)"),
        (lambda m, x: x.max(1).indices + x[:, 0], "x.max(dim)"),
        (lambda m, x: x.min(1)[1].float() * x[:, 0], "x.min(dim)"),
        (lambda m, x: x[x.max(0).indices], "x.max(dim)"),
        (lambda m, x: x * (torch.max(x, 1)[1] == 2)[:, None], "torch.max(x, dim)"),
        (lambda m, x: F.one_hot(torch.min(x, -1).indices, 3) * x, "torch.min(x, dim)"),
        (lambda m, x: torch.cat([x.max(1).indices, x[0]]), "x.max(dim)"),
        (lambda m, x: x.max(1).indices, "x.max(dim)"),
    ],
    ids=["gather", "arithmetic", "conversion", "indexing", "comparison", "one_hot", "in_a_list", "returned"],
)
def test_indices_used_later_are_refused_saying_to_use_the_values(fn, message):
    x = torch.tensor(POINTS["distinct"], dtype=torch.float64)
    fn(None, x)  # torch runs it
    module = Wrap(fn).double()
    with pytest.raises(ExportError) as info:
        export_function(module, module.forward, [TensorSpec("x", (3, 3))], ["y"], "f")
    kind = "amin" if "min" in message else "amax"
    assert str(info.value).startswith(
        f"cannot export: the indices of {message} are used: {INDICES} {message}.values or "
        f"torch.{kind}(x, dim) (in module "
    )
    assert "\n" not in str(info.value)


def test_max_over_several_dims_is_refused_as_torch_refuses_it():
    """torch's argument parser refuses torch.max(x, (0, 1)) before the export sees it (a TypeError while
    tracing, in one line); x.max((0, 1)) reaches the export, which refuses it too, saying what to use."""
    with pytest.raises(TypeError):
        torch.zeros(3, 3).max((0, 1))
    module = Wrap(lambda m, x: x.max((0, 1)).values).double()
    with pytest.raises(
        ExportError, match=r"x\.max over dim=\(0, 1\) \(one int, as torch takes; torch\.amax takes"
    ):
        export_function(module, module.forward, [TensorSpec("x", (3, 3))], ["y"], "f")


NAN = math.nan
# a NaN alone in a row, beside a larger entry, beside an equal-looking tie, first and last; a row of two NaN
# and a finite one; a row without one, whose values stay as they were
NAN_POINT = [[1.0, NAN, 3.0], [NAN, 5.0, NAN], [-0.7, -0.7, 1.1]]
NAN_CASES = {
    "amax_amin": lambda m, x: torch.cat([x.amax(-1), x.amin(0), torch.amax(x)[None], x.T.amin(-1)]),
    "max_min_dim": lambda m, x: torch.cat([x.max(1).values, x.min(0).values, x.T.max(-1)[0]]),
    "max_min_every_entry": lambda m, x: torch.stack([x.max(), x.min(), x[2].max(), x[2].min()]),
    "maximum_minimum": lambda m, x: torch.cat(
        [torch.maximum(x, x.T), torch.minimum(x, torch.full_like(x, 2.0))]
        + [torch.max(x, x[:, [2, 1, 0]]), torch.min(-x, other=x.T)]
    ),
}


DIM_TENSORS = {
    "function": lambda m, x: torch.max(x, dim=torch.tensor(0))[0],
    "method": lambda m, x: x.min(dim=torch.tensor(1)).values * 2,
    "keepdim": lambda m, x: torch.max(x, dim=torch.tensor(-1), keepdim=True).values * x,
    "other_still_positional": lambda m, x: torch.max(x, torch.tensor(0.5)) + torch.min(x, x.T),
}


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("name", sorted(NAN_CASES))
def test_a_nan_is_the_extreme_as_in_torch(name, symbol):
    """torch's extremes propagate NaN (the max of [1, nan] is nan); CasADi's fmax, which they were built on,
    passes over it, so the export gave 3 where torch gives NaN."""
    module = Wrap(NAN_CASES[name]).double()
    x = torch.tensor(NAN_POINT, dtype=torch.float64)
    function = export_function(module, module.forward, [TensorSpec("x", (3, 3))], ["y"], "f", symbol=symbol)
    expected = module(x).reshape(-1).numpy()
    got = np.asarray(function(x.numpy().ravel())).ravel()
    assert np.isnan(expected).any() and not np.isnan(expected).all()
    np.testing.assert_array_equal(np.isnan(got), np.isnan(expected))
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)


def test_the_gradient_of_max_over_a_dim_goes_to_the_first_nan_as_torchs():
    """torch.max(x, dim) returns the first NaN of a row and its index, to which its gradient goes."""
    module = Wrap(NAN_CASES["max_min_dim"]).double()
    x = torch.tensor(NAN_POINT, dtype=torch.float64)
    function = export_function(module, module.forward, [TensorSpec("x", (3, 3))], ["y"], "f")
    a = ca.MX.sym("a", 9)
    got = np.asarray(ca.Function("j", [a], [ca.jacobian(function(a), a)])(x.numpy().ravel()))
    torch_jac = torch.autograd.functional.jacobian(lambda y: module(y).reshape(-1), x).reshape(got.shape)
    np.testing.assert_array_equal(got, torch_jac.numpy())


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("name", sorted(DIM_TENSORS))
def test_a_dim_given_as_a_tensor_by_name_is_the_dim(name, symbol):
    """torch takes a tensor in max's second place for the other operand, but dim=torch.tensor(0) for the dim:
    the export took any tensor dim for the other, so torch.max(x, dim=torch.tensor(0))[0] exported the row
    max(x[0], 0), silently (torch: the columns' maxima), and x.max(dim=torch.tensor(1))[0] ended in numpy's
    "operands could not be broadcast together" past ExportError."""
    _assert_matches_torch(DIM_TENSORS[name], POINTS["distinct"], symbol)
