"""The exporter, operation by operation against torch (values and Jacobians, float64), its refusals, SX and
MX, and the exported Social-LSTM against the hand-written twin kept as an independent cross-check."""

from __future__ import annotations

import re
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from torch import nn

from predictors.export import ExportError, TensorSpec, export_function
from predictors.learned import LearnedPredictor
from predictors.nets.pooling import GridPooling
from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig
from predictors.social_lstm_predictors import SocialLSTMPredictor
from tests.predictors.handwritten.twin import SocialLSTMTwin


class Wrap(nn.Module):
    """A function of tensors as a module (its forward is what is exported)."""

    def __init__(self, fn, **modules):
        super().__init__()
        self.fn = fn
        for name, module in modules.items():
            self.add_module(name, module)

    def forward(self, *xs):
        return self.fn(self, *xs)


def check(module: nn.Module, *inputs: torch.Tensor, symbol=ca.MX, atol=1e-10):
    """``module(*inputs)`` exported: values and the Jacobian of the (first) output against torch."""
    module = module.double().eval()
    specs = [TensorSpec(f"x{i}", tuple(x.shape), x.dtype == torch.bool) for i, x in enumerate(inputs)]
    function = export_function(module, module.forward, specs, ["y"], "f", symbol=symbol)
    args = [x.double().numpy().ravel() for x in inputs]
    with torch.no_grad():
        expected = module(*inputs).reshape(-1).numpy()
    np.testing.assert_allclose(np.asarray(function(*args)).ravel(), expected, rtol=0, atol=atol)
    floats = [i for i, x in enumerate(inputs) if x.dtype != torch.bool]
    symbols = [ca.MX.sym(f"a{i}", len(a)) for i, a in enumerate(args)]
    out = function(*symbols)
    jacobian = ca.Function("j", symbols, [ca.jacobian(out, symbols[floats[0]])])
    got = np.asarray(jacobian(*args))

    def first(x):
        xs = list(inputs)
        xs[floats[0]] = x
        return module(*xs).reshape(-1)

    torch_jac = torch.autograd.functional.jacobian(first, inputs[floats[0]].double()).reshape(got.shape)
    np.testing.assert_allclose(got, torch_jac.numpy(), rtol=0, atol=1e-8)


def randn(*shape):
    return torch.randn(*shape, dtype=torch.float64)


OPERATIONS = {
    "arithmetic": (lambda m, x, y: (x * 2 - y) / (1.5 + y**2) + 3 - x, (randn(3, 4), randn(3, 4))),
    "broadcast": (lambda m, x, y: x[:, None, :] - x[None] + y, (randn(3, 2), randn(3, 1, 2))),
    "unary": (
        lambda m, x: torch.tanh(x) + torch.sigmoid(x) + F.relu(x) + F.gelu(x) + F.softplus(x) + torch.exp(x),
        (randn(2, 5),),
    ),
    "log_sqrt_abs": (lambda m, x: torch.log(x.abs() + 1) + torch.sqrt(x**2 + 1), (randn(4, 3),)),
    # every other registered element-wise operation, weighted apart so that one mapped to another shows;
    # beta * x crosses softplus's threshold in both directions
    "unary_rest": (
        lambda m, x: (
            torch.rsqrt(x.abs() + 1)
            + 2 * torch.square(x)
            + 3 * F.silu(x)
            + 4 * torch.log1p(x.abs())
            + 5 * torch.sin(x)
            + 6 * torch.cos(x)
            + 7 * torch.erf(x)
            + 8 * torch.neg(x)
            + 9 * F.leaky_relu(x, 0.2)
            + 10 * F.gelu(x, approximate="tanh")
            + 11 * F.softplus(x, beta=2.0, threshold=1.0)
        ),
        (torch.linspace(-2.0, 2.0, 12, dtype=torch.float64).reshape(3, 4),),
    ),
    "min_max_clamp": (
        lambda m, x, y: (
            torch.maximum(x, y) + 2 * torch.minimum(x, y) + 3 * x.clip(-0.5, 0.5) + torch.clamp(x, min=y)
        ),
        (randn(3, 4), randn(3, 4)),
    ),
    # ties on purpose (half of y equals x), where >= and > (or <= and <) differ
    "comparisons": (
        lambda m, x, y: (
            x * (x >= y).to(x.dtype)
            + 2 * x * (x <= y).to(x.dtype)
            + 4 * x * (x != y).to(x.dtype)
            + 8 * x * (x == y).to(x.dtype)
            + 16 * x * (x > y).to(x.dtype)
            + 32 * x * torch.lt(x, y).to(x.dtype)
        ),
        (
            torch.arange(12, dtype=torch.float64).reshape(3, 4),
            torch.arange(12, dtype=torch.float64).reshape(3, 4) + torch.tensor([0.0, 1.0, -1.0, 0.0]),
        ),
    ),
    # constants that are not all 0 (or all 1) are real terms, and one that broadcasts x to a larger shape
    # is one too, all 0 or 1 as it is
    "constants": (
        lambda m, x: (
            x * torch.tensor([1.0, 2.0, 1.0, 1.0])
            + (x + torch.tensor([0.0, 3.0, 0.0, 0.0]))
            + (x[:, :1] * torch.ones(3, 4)).sum(-1, keepdim=True)  # 4 x, not x
            + (x[:, :1] + torch.zeros(3, 4)).sum(-1, keepdim=True)
        ),
        (randn(3, 4),),
    ),
    "alpha": (
        lambda m, x, y: torch.add(x, y, alpha=2.0) + 3 * torch.sub(x, y, alpha=0.5),
        (randn(3, 4), randn(3, 4)),
    ),
    # torch.logical_not of a float is x == 0, not 1 - x
    "logical_not_float": (
        lambda m, x: x * torch.logical_not(x).to(x.dtype) + torch.logical_not(x).to(x.dtype),
        (torch.tensor([[0.0, 1.5, -2.0], [0.25, 0.0, 3.0]], dtype=torch.float64),),
    ),
    # a tensor bound, and a constant mask that is all False (no node: the other branch as it is)
    "clamp_tensor_max": (
        lambda m, x, y: torch.clamp(x, max=y) + 2 * torch.clamp(x, min=y),
        (randn(3, 4), randn(3, 4)),
    ),
    "where_all_false": (
        lambda m, x: torch.where(torch.zeros(3, 4, dtype=torch.bool), x, -2 * x),
        (randn(3, 4),),
    ),
    "log_softmax": (lambda m, x: F.log_softmax(x, dim=-1) + 2 * x.log_softmax(1), (randn(2, 3, 3),)),
    # chunk(3) of 4 columns is 2 + 2 where split(3) would be 3 + 1
    "movement_rest": (
        lambda m, x: (
            torch.cat([x.chunk(3, dim=-1)[0], 2 * x.chunk(3, dim=-1)[1]], -1).sum(1)
            + x.unbind(1)[0]
            + 3 * x.unbind(1)[2]
            + 5 * x[:, :1].squeeze(1)
            + 7 * x.view(2, 12)[:, :4]
            + 11 * torch.concat([x.narrow(1, 1, 2), x[:, :1]], dim=1).sum(1)
        ),
        (randn(2, 3, 4),),
    ),
    # a constant on the left of @ (the tensor's reflected matmul), and tensors made like x
    "constructors_rmatmul": (
        lambda m, x: (
            torch.arange(6.0, dtype=torch.float64).reshape(2, 3) @ x
            + (torch.full_like(x, 2.5) * x + 3 * x.new_ones(3, 4))[:2]
        ),
        (randn(3, 4),),
    ),
    # a plain number on the left: Python calls the tensor's reflected operator with the operands swapped
    "reflected": (lambda m, x: 2.0 / (x**2 + 1) + 1.5**x + 3.0 - x, (randn(3, 4),)),
    "method_forms": (
        lambda m, x, k: (
            x.where(k[..., None], -2 * x).swapaxes(0, 2)
            + x.type_as(k).type_as(x).swapaxes(0, 2)  # float -> bool -> float: x != 0 as 0/1
        ),
        (randn(2, 3, 2), torch.tensor([[True, False, True], [False, True, True]])),
    ),
    "linear": (lambda m, x: m.lin(x), (randn(2, 3, 5),), {"lin": nn.Linear(5, 4)}),
    "matmul_batched": (lambda m, x, y: x @ y, (randn(2, 3, 4), randn(2, 4, 5))),
    # a dot product is 0-d (it was (1,), and cat with a vector failed); a vector times a matrix either side
    "matmul_vectors": (
        lambda m, x, y, w: torch.cat([(x @ y).unsqueeze(0), x, x @ w, 2 * torch.matmul(w, y)]) + (x @ y),
        (randn(3), randn(3), randn(3, 3)),
    ),
    "matmul_2d": (lambda m, x, y: torch.matmul(x, y), (randn(2, 3, 4), randn(4, 2))),
    "cat_stack": (
        lambda m, x, y: torch.cat([torch.stack([x, y], dim=1), torch.stack([y, x], dim=1)], dim=0).sum(-1),
        (randn(3, 2), randn(3, 2)),
    ),
    # empty slices (a window of one step drops its whole past: window[..., 2:] of 2 columns), with cat along
    # the columns, the rows and a middle dim
    "empty_slices": (
        lambda m, x: (
            torch.cat([x[..., 2:], x], -1)
            + 2 * torch.cat([x[:0], x], 0)
            + 3 * torch.cat([x, x[:, 3:]], 1)
            + 4 * x[..., :0].sum(-1, keepdim=True)
        ),
        (randn(2, 3, 2),),
    ),
    "cat_middle": (lambda m, x, y: torch.cat([x, y], dim=1), (randn(2, 3, 2), randn(2, 1, 2))),
    "slice_index": (lambda m, x: x[:, 1:3, ::2] * x[0, -1, 0] + x[:, :2, None, 1], (randn(2, 4, 4),)),
    "shape_ops": (
        lambda m, x: x.reshape(3, -1).transpose(0, 1).unsqueeze(0).permute(2, 0, 1).flatten(1).T,
        (randn(3, 2, 4),),
    ),
    "expand_repeat": (lambda m, x: x.expand(2, 3, 4) + x.repeat(2, 1, 1), (randn(1, 3, 4),)),
    "sum_mean": (lambda m, x: x.sum(-1) + x.mean(dim=(0, 2), keepdim=True)[0, :, 0], (randn(2, 3, 4),)),
    "softmax": (lambda m, x: F.softmax(x, dim=1) + torch.softmax(x, -1), (randn(2, 3, 3),)),
    "where_mask": (
        lambda m, x, k: torch.where(k[..., None], x, -x),
        (randn(2, 3, 2), torch.rand(2, 3) > 0.5),
    ),
    "mask_logic": (
        lambda m, x, k: (
            x * (k | ~k).to(x.dtype)[..., None] + x * (k & (x[..., 0] > 0)).to(x.dtype)[..., None]
        ),
        (randn(2, 3, 2), torch.rand(2, 3) > 0.5),
    ),
    # torch's sum of two masks is their or and their product their and, both masks (a sum was 2 where both
    # hold); with a number the result is numeric
    "mask_arithmetic": (
        lambda m, x, k, j: (
            x * (k + j).to(x.dtype)
            + 2 * x * (k * j).to(x.dtype)
            + 4 * x * (k * j + k + (x > 0)).to(x.dtype)
            + 8 * x * (k + True).to(x.dtype)
            + 16 * x * torch.add(j, k).to(x.dtype)
            + 32 * x * (k + 1).to(x.dtype)
        ),
        (
            randn(2, 4),
            torch.tensor([[True, True, False, False]] * 2),
            torch.tensor([[True, False, True, False]] * 2),
        ),
    ),
    "layer_norm": (lambda m, x: m.norm(x), (randn(2, 3, 6),), {"norm": nn.LayerNorm(6)}),
    "attention": (
        lambda m, q, k, v, a: F.scaled_dot_product_attention(q, k, v, attn_mask=a),
        (
            randn(1, 2, 4, 3),
            randn(1, 2, 4, 3),
            randn(1, 2, 4, 5),
            (torch.rand(4, 4) > 0.4) | torch.eye(4, dtype=torch.bool),
        ),
    ),
    "einsum": (lambda m, w, v: torch.einsum("bijc,bjf->bicf", w, v), (randn(1, 3, 3, 4), randn(1, 3, 2))),
    # At a tie CasADi's fmax/fmin have slope 0.5; torch's relu has 0 at 0, leaky_relu its negative slope,
    # clamp 1 at a bound: exact zeros and bounds on purpose.
    "ties": (
        lambda m, x: (
            torch.relu(x) + 2 * F.leaky_relu(x, 0.2) + 3 * torch.clamp(x, -0.5, 0.5) + 5 * x.clamp(min=0.0)
        ),
        (torch.tensor([[0.0, 0.5, -0.5, 1.0], [-1.0, 0.0, 0.25, -0.25]], dtype=torch.float64),),
    ),
    # The scenarios' formation: robots 2.0 m apart put a neighbour exactly on a cell edge (relu(0)).
    "soft_grid_pooling_ties": (
        lambda m, p, h, n: m.pool(h, p, n),
        (
            torch.tensor([[[-1.0, -5.0], [0.0, -5.0], [1.0, -5.0], [0.3, -2.0]]], dtype=torch.float64),
            randn(1, 4, 6),
            torch.tensor([[True, True, True, True]]),
        ),
        {"pool": GridPooling(hidden_dim=6, latent_dim=3, out_dim=4, cell_side=0.8, grid_size=6, soft=True)},
    ),
    # symbolic bounds on both sides (below, inside, above, on them), also min > max (torch gives max); the
    # Jacobian with respect to the bound comes from the swapped order
    "clamp_symbolic_bounds": (
        lambda m, x, y: torch.clamp(x, min=y, max=y + 1) + 2 * x.clamp(min=y + 1, max=y),
        (
            torch.tensor([[-5.0, 0.5, 3.0, 0.0, 1.0]], dtype=torch.float64),
            torch.zeros(1, 5, dtype=torch.float64),
        ),
    ),
    "clamp_symbolic_bounds_by_bound": (
        lambda m, y, x: torch.clamp(x, min=y, max=y + 1) + 2 * x.clamp(min=y + 1, max=y),
        (
            torch.zeros(1, 5, dtype=torch.float64),
            torch.tensor([[-5.0, 0.5, 3.0, 0.0, 1.0]], dtype=torch.float64),
        ),
    ),
    # constant tensor bounds that broadcast (a row of per-column minima, a column of per-row maxima)
    "clamp_constant_tensor_bounds": (
        lambda m, x: torch.clamp(
            x, min=torch.tensor([0.0, -1.0, 0.5, 0.0]), max=torch.tensor([[1.0], [2.0]])
        ),
        (torch.tensor([[-0.5, -2.0, 0.7, 3.0], [0.5, 2.5, 0.1, 0.0]], dtype=torch.float64),),
    ),
    # a fully masked query row (an agent with nobody in range) is 0 in torch's attention, boolean or -inf mask
    "attention_empty_row": (
        lambda m, q, k, v, a: (
            F.scaled_dot_product_attention(q, k, v, attn_mask=a)
            + 2
            * F.scaled_dot_product_attention(
                q, k, v, attn_mask=torch.tensor([0.0, -float("inf"), 0.0, 0.0])[:, None].expand(4, 4)
            )
        ),
        (
            randn(1, 2, 4, 3),
            randn(1, 2, 4, 3),
            randn(1, 2, 4, 5),
            torch.tensor([[True, True, False, False], [False] * 4, [True] * 4, [False, False, True, False]]),
        ),
    ),
    # logit gaps beyond exp's range: log(softmax) was -inf (and its Jacobian NaN)
    "log_softmax_wide": (
        lambda m, x: F.log_softmax(x, dim=-1) + 2 * F.log_softmax(x, dim=0),
        (torch.tensor([[0.0, -800.0, 3.0], [1000.0, 0.0, -742.0]], dtype=torch.float64),),
    ),
    # torch reduces every dim for an empty dim list
    "sum_empty_dims": (
        lambda m, x: x.sum(dim=[]) + 2 * x.mean(dim=(), keepdim=True) + 3 * torch.sum(x, []),
        (randn(2, 3, 4),),
    ),
    # inputs below -709.8, where exp(-x) is inf: 1 / (1 + exp(-x)) had the right value and a NaN derivative
    "sigmoid_tails": (
        lambda m, x: torch.sigmoid(x) + 2 * F.silu(x),
        (torch.tensor([[-800.0, -709.9, -700.0, -1.0], [0.0, 1.0, 700.0, 800.0]], dtype=torch.float64),),
    ),
    "saturated_cells": (
        lambda m, x, h: m.lstm(x, (h, h))[0] + m.lstm(x, (h, h))[1] + m.gru(x, h),
        (1e4 * randn(4, 3), randn(4, 5)),
        {"lstm": nn.LSTMCell(3, 5), "gru": nn.GRUCell(3, 5)},
    ),
    "lstm_cell": (
        lambda m, x, h, c: m.cell(x, (h, c))[0] + m.cell(x, (h, c))[1],
        (randn(4, 3), randn(4, 5), randn(4, 5)),
        {"cell": nn.LSTMCell(3, 5)},
    ),
    "gru_cell": (lambda m, x, h: m.cell(x, h), (randn(4, 3), randn(4, 5)), {"cell": nn.GRUCell(3, 5)}),
    "soft_grid_pooling": (
        lambda m, h, p, n: m.pool(h, p, n),
        (randn(1, 5, 6), randn(1, 5, 2), torch.tensor([[True, True, False, True, True]])),
        {"pool": GridPooling(hidden_dim=6, latent_dim=3, out_dim=4, cell_side=0.8, grid_size=4, soft=True)},
    ),
}


@pytest.mark.parametrize("name", sorted(OPERATIONS))
def test_operation_matches_torch_in_values_and_jacobians(name):
    torch.manual_seed(0)
    fn, inputs, *modules = OPERATIONS[name]
    check(Wrap(fn, **(modules[0] if modules else {})), *inputs)


@pytest.mark.parametrize(
    "name", ["arithmetic", "linear", "lstm_cell", "soft_grid_pooling", "attention", "empty_slices"]
)
def test_sx_export_and_mx_function_called_with_sx(name):
    torch.manual_seed(0)
    fn, inputs, *modules = OPERATIONS[name]
    module = Wrap(fn, **(modules[0] if modules else {})).double()
    check(module, *inputs, symbol=ca.SX)
    specs = [TensorSpec(f"x{i}", tuple(x.shape), x.dtype == torch.bool) for i, x in enumerate(inputs)]
    mx = export_function(module, module.forward, specs, ["y"], "f")
    sx_args = [ca.SX.sym(f"s{i}", x.numel()) for i, x in enumerate(inputs)]
    expanded = ca.Function("g", sx_args, [mx(*sx_args)])
    args = [x.double().numpy().ravel() for x in inputs]
    np.testing.assert_allclose(np.asarray(expanded(*args)), np.asarray(mx(*args)), rtol=0, atol=1e-12)


def export(fn, *shapes, **modules):
    module = Wrap(fn, **modules).double()
    specs = [TensorSpec(f"x{i}", s) for i, s in enumerate(shapes)]
    return export_function(module, module.forward, specs, ["y"], "f")


@pytest.mark.parametrize(
    ("fn", "message"),
    [
        (lambda m, x: torch.div(x, 2.0, rounding_mode="floor"), "division with rounding_mode='floor'"),
        (lambda m, x: x.to(torch.int64).to(x.dtype), "conversion to torch.int64"),
    ],
)
def test_operations_without_a_smooth_casadi_form_are_refused(fn, message):
    """Rounding has no derivative for the solver: refused, never exported as plain division or a no-op."""
    with pytest.raises(ExportError, match=message):
        export(fn, (3, 4))


@pytest.mark.parametrize(
    "fn",
    [
        lambda m, x, k: x * (k - k),
        lambda m, x, k: x * (1 - k),
        lambda m, x, k: x - k,
        lambda m, x, k: k.sub(x),
    ],
    ids=["mask_minus_mask", "one_minus_mask", "float_minus_mask", "sub_method"],
)
def test_subtracting_a_mask_is_refused_as_torch_refuses_it(fn):
    """torch raises on any subtraction with a bool tensor; the exporter subtracted 0/1 values."""
    module = Wrap(fn).double()
    specs = [TensorSpec("x", (3,)), TensorSpec("k", (3,), True)]
    with pytest.raises(ExportError, match=r"subtraction with a bool tensor .*module 'Wrap'") as info:
        export_function(module, module.forward, specs, ["y"], "f")
    assert "\n" not in str(info.value)
    with pytest.raises(RuntimeError, match="Subtraction"):
        fn(None, randn(3), torch.tensor([True, False, True]))


def test_unsupported_operation_names_the_op_and_the_module():
    class Sorting(nn.Module):
        def forward(self, x):
            return torch.sort(x, dim=-1).values

    with pytest.raises(ExportError, match=r"unsupported operation torch\.sort .*module 'inner'") as info:
        export(lambda m, x: m.inner(x), (3, 4), inner=Sorting())
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("fn", "modules", "message"),
    [
        (
            lambda m, x: m.conv(x[0]),
            {"conv": nn.Conv1d(3, 2, 2)},
            r"unsupported operation torch\.conv1d, "
            r"inside torch\.nn\.Conv1d, a layer the export does not map \(in module 'conv'\)",
        ),
        (  # torch.functional's, as torch.cdist was before the export mapped it
            lambda m, x: torch.cartesian_prod(x[0, 0], x[0, 1]),
            {},
            r"unsupported operation torch\.cartesian_prod \(in module 'Wrap'\)",
        ),
        (lambda m, x: x.cumsum(-1), {}, r"unsupported tensor method \.cumsum\(\) \(in module 'Wrap'\)"),
        (  # a layer the export maps, running the user's activation: not "a layer the export does not map"
            lambda m, x: m.layer(x),
            {"layer": nn.TransformerEncoderLayer(4, 2, 8, activation=lambda y: y.cumsum(-1))},
            r"unsupported tensor method \.cumsum\(\), inside torch\.nn\.TransformerEncoderLayer "
            r"\(in module 'layer'\)",
        ),
    ],
    ids=["torch_nn_layer", "torch_functional", "tensor_method", "mapped_layer"],
)
def test_unsupported_operation_names_the_layer_the_user_wrote_and_where_the_supported_ones_are(
    fn, modules, message
):
    """`crowdmpc export` of a user's net with nn.MultiheadAttention (mapped since) said "unsupported operation
    torch.is_floating_point (in module 'attn')", a call the user never wrote, and torch.cdist was named
    torch.functional.cdist; neither line said where the supported operations are listed."""
    with pytest.raises(ExportError, match=message) as info:
        export(fn, (1, 3, 4), **modules)
    assert str(info.value).endswith("; the supported operations are listed in docs/extending.md, section 1")
    assert "\n" not in str(info.value)


class _Decoder(nn.TransformerDecoder):
    """A subclass with a forward of its own, which the export does not map: it runs torch's forward."""

    def forward(self, tgt, memory, *args, **kwargs):
        return super().forward(tgt, memory, *args, **kwargs)


@pytest.mark.parametrize(
    ("fn", "modules", "message"),
    [
        (  # nn.TransformerDecoder itself is mapped (as nn.TransformerEncoderLayer, which read src.is_nested
            # too); a subclass with its own forward runs it, here torch's, which reads tgt.is_nested
            lambda m, x: m.block(x, x),
            {"block": _Decoder(nn.TransformerDecoderLayer(4, 2, 8, batch_first=True), 1)},
            r"unsupported tensor attribute \.is_nested, inside _Decoder, .* \(in module 'block'\); ",
        ),
        (lambda m, x: x * x.nbytes, {}, r"unsupported tensor attribute \.nbytes \(in module 'Wrap'\); "),
    ],
    ids=["transformer_decoder", "plain"],
)
def test_an_unsupported_tensor_attribute_is_named_as_an_attribute(fn, modules, message):
    """nn.MultiheadAttention called without a mask (mapped since) read query.is_nested, a property of a
    tensor, as nn.TransformerDecoder reads tgt.is_nested: the refusal named it ".is_nested()", a method no one
    calls."""
    with pytest.raises(ExportError, match=message) as info:
        export(fn, (1, 3, 4), **modules)
    assert "()" not in str(info.value)


def test_softmax_of_a_row_of_only_minus_inf_stays_nan_as_in_torch():
    """Only attention gives a fully masked row 0; a plain softmax of all -inf is NaN in torch, and so here."""
    mask = torch.tensor([[True, False], [False, False]])

    def fn(m, x):
        return torch.softmax(torch.where(mask, x, -float("inf")), -1)

    x = torch.tensor([[0.3, -0.2], [0.1, 0.5]], dtype=torch.float64)
    got = np.asarray(export(fn, (2, 2))(x.numpy().ravel())).ravel()
    expected = fn(None, x).reshape(-1).numpy()
    assert np.isnan(expected[2:]).all() and np.isnan(got[2:]).all()
    np.testing.assert_array_equal(got[:2], expected[:2])


@pytest.mark.parametrize(
    ("fn", "message"),
    [
        (lambda m, x: m.inner(x), r"einsum 'ii->i' \(a letter repeated within one operand"),
        (
            lambda m, x: torch.tensor([x[0, 0], x[0, 1]]),
            r"TypeError while tracing \(len\(\) of a 0-d tensor\)",
        ),
        (lambda m, x: x[:, 7], r"IndexError while tracing .*module 'Wrap'"),
        # a dim out of range was taken as no dim (squeeze) or another one
        (
            lambda m, x: x[0].squeeze(-2),
            r"IndexError while tracing \(Dimension out of range .*\[-1, 0\], but got -2",
        ),
        (lambda m, x: x.sum(2), r"IndexError while tracing \(Dimension out of range .*\[-2, 1\], but got 2"),
    ],
    ids=["einsum_diagonal", "tensor_of_symbols", "index_out_of_range", "squeeze_dim", "sum_dim"],
)
def test_torch_code_that_fails_on_symbols_is_an_export_error(fn, message):
    """Torch code that raised while traced (numpy's, torch's own) escaped as a traceback; an einsum diagonal
    was a ValueError. Each is an ExportError naming the module, in one line."""

    class Diagonal(nn.Module):
        def forward(self, x):
            return torch.einsum("ii->i", x)

    with pytest.raises(ExportError, match=message) as info:
        export(fn, (2, 2), inner=Diagonal())
    assert "\n" not in str(info.value)
    if "einsum" in message:
        assert info.value.module == "inner"


def test_data_dependent_branch_is_refused_with_the_module():
    class Branching(nn.Module):
        def forward(self, x):
            return x if x.sum() > 0 else -x

    with pytest.raises(ExportError, match=r"bool\(\) of a symbolic tensor.*module 'block'"):
        export(lambda m, x: m.block(x), (3,), block=Branching())


def test_in_place_write_and_value_reads_are_refused():
    def write(m, x):
        y = x * 1
        y[0] = 0
        return y

    with pytest.raises(ExportError, match="in-place write"):
        export(write, (3,))
    with pytest.raises(ExportError, match=r"item\(\)"):
        export(lambda m, x: x * x[0].item(), (3,))
    with pytest.raises(ExportError, match=r"unsupported tensor method \.masked_fill_"):
        export(lambda m, x: x.masked_fill_(x > 0, 0.0), (3,))


def _halve_a_view(m, x):
    out = x * 1
    mean = out[..., :2]
    mean *= 0.5  # torch halves out's first two columns through the view
    return out


def _accumulate(m, x):
    total = x * 2
    total += x
    return total


def _divide(m, x):
    y = x.sum(-1)
    y /= 3.0
    return y


def _subtract(m, x):
    y = x * 2
    y -= 1.0
    return y


@pytest.mark.parametrize(
    ("fn", "operator"), [(_halve_a_view, "*="), (_accumulate, "+="), (_divide, "/="), (_subtract, "-=")]
)
def test_in_place_arithmetic_is_refused_not_rebound(fn, operator):
    """``x *= v`` changes torch's x and every view of it; the exporter bound x alone to a new tensor, so a
    view written to left the tensor it views unchanged."""
    with pytest.raises(ExportError, match=rf"in-place arithmetic x {re.escape(operator)} v") as info:
        export(fn, (2, 3))
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("fn", [F.softmax, F.log_softmax])
def test_softmax_without_dim_is_refused(fn):
    """torch's implicit dim is 0 for a 1- or 3-D input; the exporter took the last one."""
    with pytest.raises(ExportError, match=rf"{fn.__name__} without dim .*: pass dim") as info:
        export(lambda m, x: fn(x), (2, 3, 4))
    assert "\n" not in str(info.value)
    torch.manual_seed(0)
    check(Wrap(lambda m, x: fn(x, dim=0)), randn(2, 3, 4))  # dim 0 given: exported as dim 0, not the last


@pytest.mark.parametrize("pooling", ["grid", "soft", "none"])
def test_exported_social_lstm_equals_the_hand_written_twin(pooling):
    """The independent cross-check: two derivations of the same map agree to rounding."""
    torch.manual_seed(1)
    net = SocialLSTM(SocialLSTMConfig(pooling=pooling))
    predictor = SocialLSTMPredictor(net, name="cross")
    weights = {k: v.numpy() for k, v in predictor.net.state_dict().items()}
    twin = SocialLSTMTwin(weights, predictor.config)
    rng = np.random.default_rng(3)
    n_humans, n_robots, horizon = 4, 2, 5
    context_size = predictor.context_size(n_humans, n_robots)
    assert context_size == twin.context_size(n_humans, n_robots)
    context = rng.normal(0, 0.5, context_size)
    context[-(n_humans + n_robots) :] = (rng.random(n_humans + n_robots) > 0.3).astype(float)
    plan = rng.normal(0, 1.5, horizon * n_robots * 2)
    exported = predictor.to_casadi(n_humans, n_robots, horizon)
    reference = twin.prediction("cross", n_humans, n_robots, horizon)
    np.testing.assert_allclose(
        np.asarray(exported(context, plan)), np.asarray(reference(context, plan)), rtol=0, atol=1e-12
    )
    x = ca.MX.sym("x", plan.size)
    jac = [ca.Function("j", [x], [ca.jacobian(f(context, x), x)])(plan) for f in (exported, reference)]
    np.testing.assert_allclose(np.asarray(jac[0]), np.asarray(jac[1]), rtol=0, atol=1e-12)


@pytest.mark.parametrize("window", [1, 16])
def test_the_guides_example_exports_at_both_ends_of_its_window(window, monkeypatch):
    """docs/examples/window_mlp.py documents windows 1..16; with 1 its step drops the whole past window (an
    empty slice), which could not be exported. ``to_casadi`` checks parity with torch itself."""
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "docs" / "examples"))
    from window_mlp import WindowMLP, WindowMLPConfig

    torch.manual_seed(0)
    predictor = LearnedPredictor(WindowMLP(WindowMLPConfig(window=window)), name=f"window_mlp_{window}")
    assert predictor.to_casadi(2, 1, 3).n_in() == 2


class LowerTriangular:
    """A stand-in for an exported predictor: torch predicts ``L @ plan`` (a lower-triangular ``L``, so its
    Jacobian is not symmetric and a transposed one shows); the CasADi function predicts the same plus
    ``value_offset`` on its first output only (the check takes the worst output, not a mean) and ``slope``
    x (plan - the checked plan), so that its values and its Jacobian differ from torch's by exactly those
    numbers. Its context is the plan of the scene checked (each scene has its own)."""

    name = "lower_triangular"
    obs_len = 3

    def __init__(self, value_offset: float = 0.0, slope: float = 0.0):
        self.value_offset, self.slope = value_offset, slope

    def to_casadi(self, n_humans, n_robots, horizon):
        self.horizon = horizon
        size = horizon * n_robots * 2
        self.matrix = np.tril(np.arange(1.0, size * size + 1).reshape(size, size))
        context, plan = ca.MX.sym("context", size), ca.MX.sym("plan", size)
        first = np.eye(size)[0]
        out = (
            ca.mtimes(ca.DM(self.matrix), plan)
            + self.value_offset * ca.DM(first)
            + self.slope * (plan - context)
            + self.casadi_extra(plan)
        )
        return ca.Function("f", [context, plan], [out])

    def encode(self, history, mask, humans):
        from predictors.export.parity import crossing_scene, scattered_scene

        n_humans, n_robots = len(humans), history.shape[1] - len(humans)
        for scene in (crossing_scene, scattered_scene):
            scene_history, _, _, plan = scene(n_humans, n_robots, self.horizon, self.obs_len)
            if np.array_equal(scene_history, history):
                return plan.ravel()
        raise AssertionError("not a scene of the parity check")

    def rollout_tensor(self, history, mask, robots_future, humans):
        plan = robots_future.reshape(-1)
        return torch.from_numpy(self.matrix) @ plan + self.torch_extra(plan, mask)

    def casadi_extra(self, plan):
        return 0

    def torch_extra(self, plan, mask):
        return 0


class GapBlind(LowerTriangular):
    """Its CasADi function misses a term that torch has for each gap in the history."""

    def torch_extra(self, plan, mask):
        return 1e-3 * float((~np.asarray(mask)).sum())


class OverflowingGate(LowerTriangular):
    """A gate sigmoid(-plan^2) of every plan entry, in CasADi as 1 / (1 + exp(plan^2)): the same values, and
    a NaN derivative (0 * inf) once plan^2 passes exp's range, 709.8, a robot beyond 26.6 m of the origin."""

    def casadi_extra(self, plan):
        return 1 / (1 + ca.exp(plan**2))

    def torch_extra(self, plan, mask):
        return torch.sigmoid(-(plan**2))


def test_the_parity_check_measures_values_and_jacobians_apart():
    from predictors.export.parity import PARITY_TOLERANCE, check_parity, require_parity

    assert PARITY_TOLERANCE == 1e-6
    exact = check_parity(LowerTriangular(), 2, 2, 3)
    assert exact.worst < 1e-9 and exact.ok()
    # one output off by 3e-6 m, the Jacobian exact
    shifted = check_parity(LowerTriangular(value_offset=3e-6), 2, 2, 3)
    assert shifted.value_error == pytest.approx(3e-6, rel=1e-3) and shifted.jacobian_error < 1e-9
    # the Jacobian's diagonal off by 2e-6, the values exact at the checked plan
    tilted = check_parity(LowerTriangular(slope=2e-6), 2, 2, 3)
    assert tilted.jacobian_error == pytest.approx(2e-6, rel=1e-3) and tilted.value_error < 1e-9
    for parity in (shifted, tilted):
        assert parity.worst == max(parity.value_error, parity.jacobian_error) and not parity.ok()
        assert parity.ok(tolerance=1e-5)
    assert check_parity(LowerTriangular(value_offset=0.9e-6), 2, 2, 3).ok()  # within 1e-6
    with pytest.raises(ExportError) as refused:
        require_parity(LowerTriangular(slope=2e-6), 2, 2, 3)
    assert "but its Jacobians with respect to the robots' plan differ by 2.00e-06, more than 1e-06" in str(
        refused.value
    )
    assert require_parity(LowerTriangular(value_offset=0.5e-6), 2, 2, 3).ok()


def test_the_parity_scene_is_a_crowd_with_robots_moving_on():
    """The check is only as good as its scene: humans that start within the +-3 m square (pooling's reach
    sees neighbours), robots last, each ending its past within 1 m of a human (so that the prediction
    depends on the plan: robots 2.4-5.2 m away compared zero Jacobians), and a plan that starts one step
    after the last observed position (at t + 1, as every plan the solver hands the predictor)."""
    from predictors.export.parity import crossing_scene

    history, mask, humans, future = crossing_scene(3, 2, 4, obs_len=5, seed=1)
    assert history.shape == (5, 5, 2) and future.shape == (4, 2, 2) and mask.all()
    assert humans.tolist() == [0, 1, 2]
    assert np.abs(history[0, :3]).max() < 3.0 + 0.1  # the start, plus 0.02 m noise
    assert np.linalg.norm(history[-1, 3:] - history[-1, [0, 1]], axis=1).max() < 1.0
    step = future[1] - future[0]  # one step of each robot's constant velocity
    np.testing.assert_allclose(future[0] - history[-1, 3:], step, atol=1e-12)
    assert np.abs(step).min() > 0  # they move


def test_the_export_says_whether_its_jacobians_compared_anything(tmp_path, capsys):
    """One human and one robot: the parity check printed "Jacobians ... 0.0e+00" as passed where the robot
    stood out of pooling's reach and both sides' Jacobians were zero. The robot now stands beside a human,
    and the line says the largest entry, or that the net pools no neighbours (vanilla_lstm)."""
    from pipelines.cli import main

    for name, said in (
        ("social_lstm_eth", r"largest entry [1-9]\.[0-9]e-0[1-5]\)"),
        ("vanilla_lstm_eth", r"all 0: no prediction depends on the plan, the net pools no neighbours\)"),
    ):
        argv = ["export", name, "--out", str(tmp_path / f"{name}.casadi"), "--humans", "1", "--robots", "1"]
        assert main(argv) == 0
        assert re.search(said, capsys.readouterr().out)
    argv = ["export", "social_lstm_eth", "--out", str(tmp_path / "alone.casadi"), "--humans", "2", "--robots"]
    assert main([*argv, "0"]) == 0  # no plan to differentiate by: said so, not "pools no neighbours"
    assert "(tolerance 1e-06; none: no robots or no humans)" in capsys.readouterr().out


def test_the_second_parity_scene_is_scattered_with_gaps_in_the_history():
    """Agents tens of metres apart, humans seen late or gone for the last two steps (and one in the middle),
    robots always seen, and the plan still one step after the last observed position."""
    from predictors.export.parity import crossing_scene, scattered_scene

    history, mask, humans, future = scattered_scene(3, 2, 4, obs_len=9, seed=1)
    near = crossing_scene(3, 2, 4, obs_len=9, seed=1)
    assert history.shape == (9, 5, 2) and future.shape == (4, 2, 2) and humans.tolist() == [0, 1, 2]
    assert mask[:, 0].tolist() == mask[:, 2].tolist() == [False] * 4 + [True] * 5
    assert mask[:, 1].tolist() == [True] * 3 + [False] + [True] * 3 + [False] * 2
    assert mask[:, 3:].all()
    gaps = np.linalg.norm(history[:, :, None] - history[:, None], axis=-1)[:, ~np.eye(5, dtype=bool)]
    assert gaps.min() > 15.0
    np.testing.assert_allclose(future[1] - future[0], near[3][1] - near[3][0], atol=1e-12)
    np.testing.assert_allclose(future[0] - history[-1, 3:], future[1] - future[0], atol=1e-12)
    for length in range(1, 10):  # every human is seen at least once, whatever the history's length
        assert scattered_scene(3, 2, 4, obs_len=length)[1].any(axis=0).all()


@pytest.mark.parametrize(
    ("standin", "value_error", "jacobian_error"),
    [(GapBlind, 3e-3, 0.0), (OverflowingGate, 0.0, float("nan"))],  # 3 gaps: 1 + 2 in 3 steps
    ids=["gap_blind", "overflowing_gate"],
)
def test_the_parity_check_sees_what_only_gaps_or_distance_show(standin, value_error, jacobian_error):
    """A twin that ignores the history's gaps, or whose derivative overflows with agents far apart, passed a
    check whose only scene had every agent seen at every step, all within a few metres."""
    from predictors.export.parity import check_parity

    parity = check_parity(standin(), 2, 1, 3)
    assert not parity.ok()
    assert parity.value_error == pytest.approx(value_error, abs=1e-9)
    np.testing.assert_allclose(parity.jacobian_error, jacobian_error, atol=1e-9)


def test_a_nan_error_fails_the_parity_check_whichever_it_is():
    """max(0.0, nan) is 0.0 in Python: an export with NaN Jacobians passed the check."""
    from predictors.export.parity import Parity

    assert Parity(0.0, 0.0).ok() and not Parity(0.0, 1e-3).ok()
    assert not Parity(0.0, float("nan")).ok() and not Parity(float("nan"), 0.0).ok()
    assert not Parity(float("inf"), 0.0).ok()


def test_a_jacobian_that_is_nan_in_torch_too_is_named_so_not_called_a_difference():
    """A net differentiating sqrt at 0 (an agent's distance to itself) has NaN Jacobians in torch and in the
    export alike: the refusal said the export "differs from torch by nan", which sent its author looking for
    an exporter bug."""
    from predictors.export.parity import check_parity, require_parity
    from predictors.learned import LearnedPredictor
    from tests.plugins.broken_nets import SqrtDistance
    from tests.plugins.toy_predictor import ToyConfig

    predictor = LearnedPredictor(SqrtDistance(ToyConfig()), name="sqrt_distance")
    predictor._export_checked = True  # the first export's own check would refuse it before this one
    parity = check_parity(predictor, 2, 1, 3)
    assert parity.value_error < 1e-9 and parity.nonfinite == ("torch's Jacobian", "the export's Jacobian")
    with pytest.raises(ExportError) as refused:
        require_parity(predictor, 2, 1, 3)
    message = str(refused.value)
    assert message.startswith(
        "cannot export: torch's Jacobian and the export's Jacobian with respect to the robots' plan hold NaN "
        "or inf"
    ), message
    assert "differs" not in message and "sqrt" in message and "torch.norm" in message and "\n" not in message


@pytest.mark.parametrize(
    ("net", "cause"),
    [
        ("DetachesItsPosition", "detach() (in module 'DetachesItsPosition') has no CasADi counterpart: the "
         "exported function would differentiate through it; the exported prediction agrees with torch"),
        ("VelocityWithoutGradients", "the exported prediction agrees with torch"),
    ],
)  # fmt: skip
def test_jacobians_that_differ_where_values_agree_name_the_stopped_gradient(net, cause):
    """The export maps detach() to the identity (CasADi has no stop-gradient), so a net detaching on its
    predicting path was refused with "differs from torch by 0.00e+00 (values) and 1.04e-01 (Jacobians)",
    which named neither the detach nor that only the derivatives differed."""
    import tests.plugins.broken_nets as broken
    from predictors.learned import LearnedPredictor
    from tests.plugins.toy_predictor import ToyConfig

    predictor = LearnedPredictor(getattr(broken, net)(ToyConfig()), name="stops")
    with pytest.raises(ExportError) as refused:
        predictor.to_casadi(2, 1, 3)
    message = str(refused.value)
    assert message.startswith(f"cannot export: {cause}"), message
    assert "but its Jacobians with respect to the robots' plan differ by" in message and "\n" not in message
    if net == "VelocityWithoutGradients":
        assert "a detach(), a torch.no_grad() block or a straight-through trick" in message


def test_a_net_that_draws_random_numbers_is_refused_as_not_deterministic(monkeypatch):
    """A net adding Python's random.random() to its steps was refused with "the exported prediction differs
    from torch by 6.53e-03 (values)", which sent its author looking for an exporter bug: the export holds
    one draw, each torch rollout another. (Such a net is refused as it loads, on the contract's synthetic
    batch: the load check is left out here, as for a net whose draws that batch does not meet.)"""
    import predictors.learned
    from predictors.learned import LearnedPredictor

    monkeypatch.setattr(predictors.learned, "check_predictor_contract", lambda *args, **kwargs: None)
    from tests.plugins.broken_nets import DrawsInPython
    from tests.plugins.toy_predictor import ToyConfig

    predictor = LearnedPredictor(DrawsInPython(ToyConfig()), name="draws")
    with pytest.raises(ExportError) as refused:
        predictor.to_casadi(2, 1, 3)
    message = str(refused.value)
    assert message.startswith(
        "cannot export: torch's prediction is not deterministic: two rollouts of the same scene differ by "
    ), message
    assert "only while training" in message and "(in module 'draws')" in message and "\n" not in message
