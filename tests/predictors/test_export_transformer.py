"""nn.TransformerEncoderLayer and nn.TransformerEncoder exported against torch in float64: their output and
its Jacobians with respect to every float input, for each way of building and calling them (batch first or
not, one sequence, norm first or last, relu, gelu, a callable or a module as the activation, no bias,
boolean, float and symbolic masks, the causal hint; the encoder's layers, its final norm or none, and its
detection of a causal mask), in MX and SX; what torch refuses, refused in one line; and a small trajectory
transformer, a predictor of the step contract, exported through LearnedPredictor.to_casadi.

Exporting nn.TransformerEncoderLayer(batch_first=True) was refused ("unsupported tensor attribute
.is_nested, inside torch.nn.TransformerEncoderLayer, a layer the export does not map"); with
batch_first=False it ran through torch's forward, never checked against torch.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass
from typing import TypeVar

import casadi as ca
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from torch import nn

from predictors.export import ExportError, TensorSpec, export_function
from predictors.export.parity import check_parity
from predictors.learned import LearnedPredictor
from tests.predictors.test_export import Wrap
from tests.predictors.test_export_attention import (
    INF,
    _export,
    _outputs,
    _torch_values,
    assert_jacobians_match,
    randn,
)

Module = TypeVar("Module", bound=nn.Module)


def _drawn(module: Module) -> Module:
    """Every parameter drawn: torch starts the biases at 0 and the norms' weights at 1, where a bias or a
    weight put in the wrong place would not show (and an encoder's layers start as copies of one)."""
    torch.manual_seed(1)
    with torch.no_grad():
        for parameter in module.parameters():
            parameter.normal_(0.0, 0.5)
    return module


def layer(*args, **kwargs) -> nn.TransformerEncoderLayer:
    return _drawn(nn.TransformerEncoderLayer(*args, **kwargs))


def encoder(num_layers: int, norm: bool, *, nested: bool = True, **kwargs) -> nn.TransformerEncoder:
    inner = nn.TransformerEncoderLayer(4, 2, 8, **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torch's note that layers of these settings take no nested tensors
        built = nn.TransformerEncoder(
            inner, num_layers, norm=nn.LayerNorm(4) if norm else None, enable_nested_tensor=nested
        )
    return _drawn(built)


# keys 1 (of sequence 0) and 2 (of sequence 1) padded: not only the ends of the sequences, so that torch's
# encoder keeps its padded tensor (see test_an_encoder_padded_at_the_ends_...)
PADDED = torch.tensor([[False, True, False], [False, False, True]])
BLOCKED = torch.tensor([[False, True, False], [False] * 3, [True, False, False]])
CAUSAL_FLOAT = nn.Transformer.generate_square_subsequent_mask(3, dtype=torch.float64)
CAUSAL_BOOL = torch.ones(3, 3, dtype=torch.bool).triu(1)
# a float mask per sequence and head (N * H, L, S), -inf on some keys of every other head
PER_HEAD = torch.where(
    BLOCKED.repeat(4, 1, 1) & (torch.arange(4) % 2 == 0)[:, None, None], -INF, randn(4, 3, 3)
)


def _call(**call):
    return lambda m, x: m.enc(x, **call)


# name: (module, forward of the wrapping module, inputs)
CASES = {
    "batch_first": (layer(4, 2, 8, batch_first=True), _call(), (randn(2, 3, 4),)),
    "sequence_first": (layer(4, 2, 8), _call(src_key_padding_mask=PADDED), (randn(3, 2, 4),)),
    "one_sequence": (
        layer(4, 2, 8, batch_first=True),
        _call(src_key_padding_mask=torch.tensor([False, True, False]), src_mask=BLOCKED),
        (randn(3, 4),),
    ),
    "norm_first_gelu": (
        layer(4, 2, 8, batch_first=True, norm_first=True, activation="gelu"),
        _call(),
        (randn(2, 3, 4),),
    ),
    "gelu_callable": (layer(4, 2, 8, batch_first=True, activation=F.gelu), _call(), (randn(2, 3, 4),)),
    "tanh_gelu_module": (
        layer(4, 2, 8, activation=nn.GELU(approximate="tanh"), norm_first=True),
        _call(),
        (randn(3, 2, 4),),
    ),
    "any_callable": (
        layer(4, 2, 8, batch_first=True, activation=functools.partial(F.leaky_relu, negative_slope=0.2)),
        _call(),
        (randn(2, 3, 4),),
    ),
    "no_bias": (layer(4, 2, 8, batch_first=True, bias=False), _call(), (randn(2, 3, 4),)),
    "one_head_no_dropout": (layer(4, 1, 6, dropout=0.0, batch_first=True), _call(), (randn(2, 3, 4),)),
    "bool_masks": (
        layer(4, 2, 8, batch_first=True),
        _call(src_mask=BLOCKED, src_key_padding_mask=PADDED),
        (randn(2, 3, 4),),
    ),
    "float_masks": (
        layer(4, 2, 8, batch_first=True),
        _call(
            src_mask=PER_HEAD,
            src_key_padding_mask=torch.tensor([[0.0, -INF, 0.5], [-1.0, 0.0, 0.0]], dtype=torch.float64),
        ),
        (randn(2, 3, 4),),
    ),
    "causal": (
        layer(4, 2, 8, batch_first=True),
        _call(src_mask=CAUSAL_FLOAT, is_causal=True),
        (randn(2, 3, 4),),
    ),
    "causal_with_padding": (
        layer(4, 2, 8, norm_first=True),
        _call(src_mask=CAUSAL_BOOL, src_key_padding_mask=PADDED, is_causal=True),
        (randn(3, 2, 4),),
    ),
    # masks given as inputs of the exported function (a neighbour mask the MPC passes in), one of them float
    "symbolic_masks": (
        layer(4, 2, 8, batch_first=True),
        lambda m, x, padded, blocked: m.enc(x, src_mask=blocked, src_key_padding_mask=padded),
        (randn(2, 3, 4), PADDED, BLOCKED),
    ),
    "symbolic_float_padding": (
        layer(4, 2, 8, batch_first=True),
        lambda m, x, padded: m.enc(x, src_key_padding_mask=padded),
        (randn(2, 3, 4), torch.tensor([[0.0, -1.0, 0.5], [-2.0, 0.0, 0.3]], dtype=torch.float64)),
    ),
    "encoder_with_norm": (
        encoder(2, True, batch_first=True),
        _call(src_key_padding_mask=PADDED),
        (randn(2, 3, 4),),
    ),
    "encoder_sequence_first_without_norm": (
        encoder(3, False, nested=False, dropout=0.3, activation="gelu"),
        _call(mask=BLOCKED),
        (randn(3, 2, 4),),
    ),
    # is_causal=None: torch compares the mask with the causal one and, finding it, passes the hint on
    "encoder_detects_a_causal_mask": (
        encoder(2, True, batch_first=True),
        _call(mask=CAUSAL_FLOAT),
        (randn(2, 3, 4),),
    ),
    "encoder_causal_hint_with_padding": (
        encoder(2, False, batch_first=True),
        _call(mask=CAUSAL_BOOL, src_key_padding_mask=PADDED, is_causal=True),
        (randn(2, 3, 4),),
    ),
    "encoder_norm_first_one_sequence": (
        encoder(2, True, batch_first=True, norm_first=True),
        _call(mask=BLOCKED),
        (randn(3, 4),),
    ),
    "encoder_symbolic_padding": (
        encoder(2, True, batch_first=True),
        lambda m, x, padded: m.enc(x, src_key_padding_mask=padded),
        (randn(2, 3, 4), PADDED),
    ),
}

# Float masks other than 0 / -inf: torch's encoder layer without gradients (its fast path: batch first, eval,
# no_grad) reads them as boolean, a nonzero entry leaving its key out (float_masks' is NaN there), where with
# gradients it adds them to the scores, as the export does.
ADDED_FLOAT_MASKS = {"float_masks", "symbolic_float_padding"}


def assert_matches_torch(wrapped: nn.Module, inputs, symbol, *, fast_path: bool) -> None:
    """The export's values (1e-10) and Jacobians with respect to every float input (1e-8) against torch's
    with gradients, and its values against torch's without (its fast path where it may take one) where
    ``fast_path`` says they agree."""
    function = _export(wrapped, inputs, symbol)
    args = [x.double().numpy().ravel() for x in inputs]
    (got,) = (np.asarray(y).ravel() for y in _outputs(function(*args)))
    for with_grad in (not fast_path, True):
        (expected,) = _torch_values(wrapped, inputs, with_grad=with_grad)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10)
    assert_jacobians_match(wrapped, function, inputs, args)


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_transformer_encoder_matches_torch_in_values_and_jacobians(name, symbol):
    module, fn, inputs = CASES[name]
    wrapped = Wrap(fn, enc=module).double().eval()
    assert_matches_torch(wrapped, inputs, symbol, fast_path=name not in ADDED_FLOAT_MASKS)


def _with_gradients(module: nn.Module, x: torch.Tensor, **call) -> np.ndarray:
    return module(x.clone().requires_grad_(), **call).detach().numpy()


def _exported(module: nn.Module, x: torch.Tensor, **call) -> np.ndarray:
    wrapped = Wrap(_call(**call), enc=module).double().eval()
    return np.asarray(_export(wrapped, (x,))(x.numpy().ravel())).reshape(x.shape)


def test_a_sequence_whose_every_key_is_padded_is_computed_as_torch_with_gradients():
    """Its attention adds out_proj's bias only, as torch's scaled dot-product attention gives weights 0 (the
    layer asks for no attention weights); torch's fast path, taken without gradients, gives NaN there."""
    module = layer(4, 2, 8, batch_first=True).double().eval()
    padded = torch.tensor([[False, True, False], [True, True, True]])
    x = randn(2, 3, 4)
    got = _exported(module, x, src_key_padding_mask=padded)
    np.testing.assert_allclose(
        got, _with_gradients(module, x, src_key_padding_mask=padded), rtol=0, atol=1e-10
    )
    assert np.isfinite(got).all()


@pytest.mark.filterwarnings("ignore:The PyTorch API of nested tensors")  # torch's fast path, run to compare
def test_an_encoder_padded_at_the_ends_is_computed_at_the_padded_positions_too():
    """torch's encoder without gradients runs a padding mask that pads only the ends of the sequences as a
    nested tensor and gives 0 at the padded positions (before its norm); with gradients, as the export, it
    computes them as any other position."""
    module = encoder(2, True, batch_first=True).double().eval()
    padded = torch.tensor([[False, False, True], [False, True, True]])
    x = randn(2, 3, 4)
    got = _exported(module, x, src_key_padding_mask=padded)
    np.testing.assert_allclose(
        got, _with_gradients(module, x, src_key_padding_mask=padded), rtol=0, atol=1e-10
    )


@pytest.mark.parametrize(
    ("module", "call", "message"),
    [
        (
            lambda: layer(4, 2, 8, batch_first=True),
            lambda m, x: m.enc(x, src_mask=torch.zeros(3, 3, dtype=torch.int64)),
            r"nn\.TransformerEncoderLayer src_mask of dtype torch\.int64 \(bool or floating, as torch\)",
        ),
        (
            lambda: layer(4, 2, 8, batch_first=True),
            lambda m, x: m.enc(x, is_causal=True),
            r"nn\.TransformerEncoderLayer with is_causal=True and no src_mask",
        ),
        (
            lambda: layer(4, 2, 8, batch_first=True),
            lambda m, x: m.enc(x[..., :3]),
            r"nn\.TransformerEncoderLayer src of shape \(2, 3, 3\) \(expected \(S, E\) or \(N, S, E\) with "
            r"E = d_model = 4, as torch\)",
        ),
        (
            lambda: encoder(2, True, batch_first=True),
            lambda m, x: m.enc(x, src_key_padding_mask=torch.zeros(2, 3, dtype=torch.int32)),
            r"nn\.TransformerEncoder src_key_padding_mask of dtype torch\.int32",
        ),
        (
            lambda: encoder(2, True, batch_first=True),
            lambda m, x: m.enc(x, is_causal=True),
            r"nn\.TransformerEncoder with is_causal=True and no mask",
        ),
    ],
    ids=["integer_mask", "causal_without_a_mask", "width", "encoder_integer_mask", "encoder_causal"],
)
def test_what_torch_refuses_is_refused_in_one_line_naming_the_argument(module, call, message):
    assert_refused_as_torch(Wrap(call, enc=module()), "enc", message)


def assert_refused_as_torch(wrapped: nn.Module, name: str, message: str) -> None:
    """``wrapped`` (a Wrap holding the layer as ``name``), which torch refuses on a (2, 3, 4) input, is
    refused by the export in one line matching ``message`` and naming the module."""
    wrapped = wrapped.double().eval()
    x = randn(2, 3, 4)
    with pytest.raises((RuntimeError, AssertionError)):
        wrapped(x.clone().requires_grad_())
    with pytest.raises(ExportError, match=message + rf".*\(in module '{name}'\)") as info:
        export_function(wrapped, wrapped.forward, [TensorSpec("x", tuple(x.shape))], ["y"], "f")
    assert "\n" not in str(info.value)


# --------------------------------------------------------------------------------- a trajectory transformer
@dataclass(frozen=True)
class TrajectoryTransformerConfig:
    window: int = 4  # displacements the temporal encoder sees
    width: int = 8


class TrajectoryTransformer(nn.Module):
    """Per agent, a causal transformer encoder over its last K displacements; then one encoder layer over the
    agents, each attending to its neighbours (so that the humans' predictions depend on the robots' plan);
    a linear head gives the next displacement. The state is the window of displacements, (B, N, K, 2)."""

    config_class = TrajectoryTransformerConfig
    head_type = "point"

    def __init__(self, config: TrajectoryTransformerConfig = TrajectoryTransformerConfig()):
        super().__init__()
        self.config = config
        width = config.width
        self.embed = nn.Linear(2, width)
        self.steps = nn.Parameter(0.1 * torch.randn(config.window, width))  # where in the window
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # torch's note on nested tensors (norm_first)
            self.temporal = nn.TransformerEncoder(
                nn.TransformerEncoderLayer(width, 2, 2 * width, dropout=0.1, batch_first=True),
                2,
                norm=nn.LayerNorm(width),
            )
        self.social = nn.TransformerEncoderLayer(width, 2, 2 * width, batch_first=True, norm_first=True)
        self.head = nn.Linear(width, 2)

    def _out(self, window: torch.Tensor, neighbours: torch.Tensor) -> torch.Tensor:
        batch, agents, steps, _ = window.shape
        tokens = self.embed(window.reshape(batch * agents, steps, 2) * 4.0) + self.steps
        causal = nn.Transformer.generate_square_subsequent_mask(steps, dtype=window.dtype)
        summary = self.temporal(tokens, mask=causal, is_causal=True)[:, -1].reshape(batch, agents, -1)
        return self.head(self.social(summary, src_key_padding_mask=~neighbours))

    def encode(self, positions, mask):
        batch, length, agents, _ = positions.shape
        window = positions.new_zeros(batch, agents, self.config.window, 2)
        for t in range(1, length):
            seen = (mask[:, t - 1] & mask[:, t])[..., None]
            step = (positions[:, t] - positions[:, t - 1]) * seen.to(positions.dtype)
            window = torch.cat([window[:, :, 1:], step[:, :, None]], dim=2)
        return window, self._out(window, mask[:, -1])

    def decode_step(self, window, prev, cur, neighbours):
        window = torch.cat([window[:, :, 1:], (cur - prev)[:, :, None]], dim=2)
        return window, self._out(window, neighbours)


def test_a_trajectory_transformer_exports_through_the_predictor():
    """to_casadi checks parity with torch itself (values and Jacobians with respect to the robots' plan, on a
    crowd and on a scattered scene with gaps), on its first export; here again at a larger size."""
    torch.manual_seed(0)
    predictor = LearnedPredictor(TrajectoryTransformer().double(), name="trajectory_transformer")
    function = predictor.to_casadi(2, 1, 3)
    assert function.n_in() == 2
    parity = check_parity(predictor, 3, 2, 4)
    assert parity.ok(), parity
    assert parity.coupling > 1e-3  # the humans' predictions depend on the plan: the Jacobians compared
