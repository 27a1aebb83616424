"""nn.MultiheadAttention exported against torch in float64: its output and weights, and their Jacobians with
respect to every float input, for each way of building and calling the layer (batch first or not, one
sequence, packed or separate projections, no bias, add_bias_kv, add_zero_attn, dropout in eval, boolean,
float and symbolic masks, the causal hint), in MX and SX; what torch refuses, refused in one line.

`crowdmpc export` of a user's net with nn.MultiheadAttention was refused ("unsupported tensor attribute
.is_nested, inside torch.nn.MultiheadAttention, a layer the export does not map"), and docs/extending.md told
users to rewrite it with F.scaled_dot_product_attention.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import torch
from torch import nn

from predictors.export import ExportError, TensorSpec, export_function
from tests.predictors.test_export import Wrap

INF = float("inf")


def randn(*shape):
    return torch.randn(*shape, dtype=torch.float64)


def layer(*args, **kwargs) -> nn.MultiheadAttention:
    torch.manual_seed(1)
    attention = nn.MultiheadAttention(*args, **kwargs)
    if attention.in_proj_bias is not None:  # torch starts them at 0, where a wrong bias would not show
        with torch.no_grad():
            attention.in_proj_bias.normal_()
            attention.out_proj.bias.normal_()
    return attention


# keys 1 (of sequence 0) and 2 (of sequence 1) padded, and the attention masks below leave every query a
# key (see the next test for one that has none)
PADDED = torch.tensor([[False, True, False], [False, False, True]])
# per head (H = 2) of one sequence, beside its padding mask
BLOCKED_PER_HEAD = torch.tensor(
    [[[False, False, True], [True, False, False], [False] * 3], [[False] * 3] * 3]
)
PADDED_FLOAT = torch.zeros(2, 3, dtype=torch.float64).masked_fill(PADDED, -INF)
CAUSAL_FLOAT = nn.Transformer.generate_square_subsequent_mask(3, dtype=torch.float64)


def _self(**call):
    return lambda m, x: m.attn(x, x, x, **call)


# name: (layer, forward of the wrapping module, inputs)
CASES = {
    "batch_first": (layer(4, 2, batch_first=True), _self(), (randn(2, 3, 4),)),
    "sequence_first_cross": (
        layer(4, 2),
        lambda m, q, kv: m.attn(q, kv, kv),
        (randn(3, 2, 4), randn(5, 2, 4)),
    ),
    "three_inputs_without_weights": (
        layer(4, 2, batch_first=True),
        lambda m, q, k, v: m.attn(q, k, v, need_weights=False)[0],
        (randn(2, 3, 4), randn(2, 5, 4), randn(2, 5, 4)),
    ),
    "weights_per_head": (layer(4, 2, batch_first=True), _self(average_attn_weights=False), (randn(2, 3, 4),)),
    "kdim_vdim": (
        layer(4, 2, batch_first=True, kdim=3, vdim=6),
        lambda m, q, k, v: m.attn(q, k, v),
        (randn(2, 3, 4), randn(2, 5, 3), randn(2, 5, 6)),
    ),
    "no_bias": (layer(4, 2, bias=False, batch_first=True), _self(), (randn(2, 3, 4),)),
    "dropout_in_eval": (layer(4, 2, dropout=0.5, batch_first=True), _self(), (randn(2, 3, 4),)),
    "bias_kv_zero_attn": (
        layer(4, 2, add_bias_kv=True, add_zero_attn=True, batch_first=True),
        _self(key_padding_mask=PADDED, attn_mask=torch.tensor([[False, True, False]] * 3)),
        (randn(2, 3, 4),),
    ),
    "bias_kv_zero_attn_without_weights": (
        layer(4, 2, add_bias_kv=True, add_zero_attn=True),
        lambda m, x: m.attn(x, x, x, key_padding_mask=PADDED, need_weights=False)[0],
        (randn(3, 2, 4),),
    ),
    "bool_masks": (
        layer(4, 2, batch_first=True),
        _self(
            key_padding_mask=PADDED,
            attn_mask=torch.tensor([[False, True, False], [False] * 3, [True, False, False]]),
        ),
        (randn(2, 3, 4),),
    ),
    "bool_masks_without_weights": (
        layer(4, 2, batch_first=True),
        lambda m, x: m.attn(
            x, x, x, key_padding_mask=PADDED, attn_mask=PADDED[:1].expand(3, 3), need_weights=False
        )[0],
        (randn(2, 3, 4),),
    ),
    # a float mask per sequence and head (N * H, L, S), some -inf, and a float padding mask
    "float_masks": (
        layer(4, 2, batch_first=True),
        _self(
            key_padding_mask=torch.tensor([[0.0, -INF, 0.5], [-1.0, 0.0, 0.0]], dtype=torch.float64),
            attn_mask=torch.where(
                torch.tensor([[False, True, False], [False, False, True], [False, True, True]]).repeat(
                    4, 1, 1
                )
                & (torch.arange(4) % 2 == 0)[:, None, None],  # every other head, keys 1 and 2 of some queries
                -INF,
                randn(4, 3, 3),
            ),
        ),
        (randn(2, 3, 4),),
    ),
    "one_sequence": (
        layer(4, 2),
        _self(key_padding_mask=torch.tensor([False, True, False]), attn_mask=BLOCKED_PER_HEAD),
        (randn(3, 4),),
    ),
    "causal_without_weights": (
        layer(4, 2, batch_first=True),
        lambda m, x: m.attn(x, x, x, attn_mask=CAUSAL_FLOAT, is_causal=True, need_weights=False)[0],
        (randn(2, 3, 4),),
    ),
    "causal_with_weights": (
        layer(4, 2, batch_first=True),
        _self(attn_mask=CAUSAL_FLOAT, is_causal=True),
        (randn(2, 3, 4),),
    ),
    "causal_with_padding": (
        layer(4, 2, batch_first=True),
        lambda m, x: m.attn(
            x, x, x, key_padding_mask=PADDED_FLOAT, attn_mask=CAUSAL_FLOAT, is_causal=True, need_weights=False
        )[0],
        (randn(2, 3, 4),),
    ),
    # masks given as inputs of the exported function (a neighbour mask the MPC passes in)
    "symbolic_masks": (
        layer(4, 2, batch_first=True),
        lambda m, x, padded, blocked: m.attn(x, x, x, key_padding_mask=padded, attn_mask=blocked),
        (randn(2, 3, 4), PADDED, torch.tensor([[False, True, False], [False] * 3, [True, False, False]])),
    ),
    "symbolic_masks_without_weights": (
        layer(4, 2, batch_first=True),
        lambda m, x, padded: m.attn(x, x, x, key_padding_mask=padded, need_weights=False)[0],
        (randn(2, 3, 4), PADDED),
    ),
}


def _outputs(value) -> tuple[torch.Tensor, ...]:
    return tuple(value) if isinstance(value, tuple) else (value,)


def _export(module: nn.Module, inputs, symbol=ca.MX) -> ca.Function:
    specs = [TensorSpec(f"x{i}", tuple(x.shape), x.dtype == torch.bool) for i, x in enumerate(inputs)]
    with torch.no_grad():
        count = len(_outputs(module(*inputs)))
    return export_function(module, module.forward, specs, [f"y{i}" for i in range(count)], "f", symbol=symbol)


def _torch_values(module: nn.Module, inputs, *, with_grad: bool) -> list[np.ndarray]:
    """torch's outputs: under no_grad (its fast path where the call allows one) or with gradients (its
    F.multi_head_attention_forward, whose Jacobians are compared)."""
    if with_grad:
        inputs = [x.clone().requires_grad_() if x.dtype != torch.bool else x for x in inputs]
        return [y.detach().reshape(-1).numpy() for y in _outputs(module(*inputs))]
    with torch.no_grad():
        return [y.reshape(-1).numpy() for y in _outputs(module(*inputs))]


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_multihead_attention_matches_torch_in_values_and_jacobians(name, symbol):
    attention, fn, inputs = CASES[name]
    module = Wrap(fn, attn=attention).double().eval()
    function = _export(module, inputs, symbol)
    args = [x.double().numpy().ravel() for x in inputs]
    got = [np.asarray(y).ravel() for y in _outputs(function(*args))]
    for with_grad in (False, True):
        expected = _torch_values(module, inputs, with_grad=with_grad)
        assert len(got) == len(expected)
        for g, e in zip(got, expected, strict=True):
            np.testing.assert_allclose(g, e, rtol=0, atol=1e-10)
    assert_jacobians_match(module, function, inputs, args)


def assert_jacobians_match(module: nn.Module, function: ca.Function, inputs, args) -> None:
    """The Jacobians of ``function`` (``module`` exported) with respect to each float input, at ``args``,
    against torch's autograd of ``module`` at ``inputs`` (every output stacked), to 1e-8."""
    symbols = [ca.MX.sym(f"a{i}", len(a)) for i, a in enumerate(args)]
    outs = _outputs(function(*symbols))
    for i, x in enumerate(inputs):
        if x.dtype == torch.bool:
            continue

        def along(z, i=i):
            xs = list(inputs)
            xs[i] = z
            return torch.cat([y.reshape(-1) for y in _outputs(module(*xs))])

        jacobian = ca.Function("j", symbols, [ca.jacobian(ca.vertcat(*outs), symbols[i])])
        torch_jacobian = torch.autograd.functional.jacobian(along, x).reshape(-1, x.numel())
        np.testing.assert_allclose(np.asarray(jacobian(*args)), torch_jacobian.numpy(), rtol=0, atol=1e-8)


def test_a_query_whose_every_key_is_masked_is_nan_with_weights_and_zero_without_as_in_torch():
    """torch's F.multi_head_attention_forward: a plain softmax (NaN) when it returns the weights, its
    scaled dot-product attention (weights 0: the output is out_proj's bias) when not. (Its inference fast
    path, taken under no_grad for self-attention, gives NaN in both.)"""
    attention = layer(4, 2, batch_first=True)
    blocked = torch.tensor([[False, False, False], [True, True, True], [False, True, False]])
    x = randn(1, 3, 4)
    for need_weights in (True, False):
        module = Wrap(
            lambda m, y, w=need_weights: m.attn(y, y, y, attn_mask=blocked, need_weights=w)[0], attn=attention
        )
        module = module.double().eval()
        got = np.asarray(_export(module, (x,))(x.numpy().ravel())).reshape(3, 4)
        expected = module(x.clone().requires_grad_()).detach()[0].numpy()
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10)
        assert np.isnan(got[1]).all() == need_weights
    np.testing.assert_allclose(got[1], attention.out_proj.bias.detach().numpy(), rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (
            lambda m, x: m.attn(x, x, x, attn_mask=torch.zeros(3, 3, dtype=torch.int64))[0],
            r"nn\.MultiheadAttention attn_mask of dtype torch\.int64 \(bool or floating, as torch\)",
        ),
        (
            lambda m, x: m.attn(x, x, x, is_causal=True)[0],
            r"nn\.MultiheadAttention with is_causal=True and no attn_mask",
        ),
        (
            lambda m, x: m.attn(x, x, x, key_padding_mask=torch.zeros(3, dtype=torch.bool))[0],
            r"nn\.MultiheadAttention key_padding_mask of shape \(3,\) \(expected \(2, 3\), as torch\)",
        ),
        (
            lambda m, x: m.attn(x[..., :3], x[..., :3], x[..., :3])[0],
            r"nn\.MultiheadAttention query of shape \(2, 3, 3\) \(expected \(L, 4\) or \(N, L, E\) "
            r"with E = 4",
        ),
    ],
    ids=["integer_mask", "causal_without_a_mask", "padding_mask_shape", "query_width"],
)
def test_what_torch_refuses_is_refused_in_one_line_naming_the_argument(call, message):
    module = Wrap(call, attn=layer(4, 2, batch_first=True)).double().eval()
    x = randn(2, 3, 4)
    with pytest.raises((RuntimeError, AssertionError)):
        module(x)
    with pytest.raises(ExportError, match=message + r".*\(in module 'attn'\)") as info:
        _export_refused(module, x)
    assert "\n" not in str(info.value)


def _export_refused(module: nn.Module, x: torch.Tensor) -> None:
    export_function(module, module.forward, [TensorSpec("x", tuple(x.shape))], ["y"], "f")


EMPTY_BATCH = {
    "matmul": lambda m, x: x @ x.transpose(-1, -2),
    "sdpa": lambda m, x: torch.nn.functional.scaled_dot_product_attention(x, x, x),
    "mha": lambda m, x: m.a(x, x, x, need_weights=False)[0],
    "mha_weights": lambda m, x: m.a(x, x, x)[1],
}


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("name", sorted(EMPTY_BATCH))
def test_attention_over_a_batch_of_none_exports_as_torch_runs_it(name, symbol):
    """A batch of 0 (a net attending over the humans of a crowd of none) ended its export in "AssertionError:
    matrix (0, 1) does not hold a tensor of shape (0, 3, 3)", a traceback past ExportError: a batched
    matmul of no blocks was vertcat's 0-by-1. Torch gives an empty result of its shape, as the export now."""
    torch.manual_seed(0)
    module = Wrap(EMPTY_BATCH[name], a=nn.MultiheadAttention(4, 2, batch_first=True)).double()
    spec = TensorSpec("x", (0, 3, 4))
    function = export_function(module, module.forward, [spec], ["y"], "f", symbol=symbol)
    with torch.no_grad():
        expected = module(torch.zeros(0, 3, 4, dtype=torch.float64))
    assert expected.numel() == 0 and function.size_out(0) == (0, 1)


NO_KEYS = {
    "sdpa": lambda m, x: torch.nn.functional.scaled_dot_product_attention(x, x[:, :0], x[:, :0]),
    "mha": lambda m, x: m.a(x, x[:, :0], x[:, :0], need_weights=False)[0],
    "mha_weights": lambda m, x: m.a(x, x[:, :0], x[:, :0])[1],
    "decoder_layer": lambda m, x: m.d(x, x[:, :0]),
    "softmax": lambda m, x: torch.softmax(x[..., :0], -1) + torch.log_softmax(x[..., :0], -1),
}


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("name", sorted(NO_KEYS))
def test_attention_over_no_key_exports_as_torch_runs_it(name, symbol):
    """Queries attending over no key (a robot's neighbours in a crowd of none): torch gives the output
    projection's bias (its weights, rows of no entry); the export refused every such net with CasADi's
    'Assertion "stop<=len" failed' (softmax_rows took the maximum of a row of none)."""
    torch.manual_seed(0)
    attention = nn.MultiheadAttention(4, 2, batch_first=True)
    nn.init.normal_(attention.out_proj.bias)  # torch's zeros would hide a missing bias
    layer = nn.TransformerDecoderLayer(4, 2, 8, dropout=0.0, batch_first=True)
    module = Wrap(NO_KEYS[name], a=attention, d=layer).double()
    spec = TensorSpec("x", (2, 3, 4))
    function = export_function(module, module.forward, [spec], ["y"], "f", symbol=symbol)
    x = torch.linspace(-1, 1, 24, dtype=torch.float64).reshape(2, 3, 4)
    with torch.no_grad():
        expected = module(x).reshape(-1).numpy()
    got = np.asarray(function(x.numpy().ravel())).ravel()
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10)
