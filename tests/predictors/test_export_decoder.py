"""nn.TransformerDecoderLayer, nn.TransformerDecoder and nn.Transformer exported against torch in float64:
their output and its Jacobians with respect to every float input (the target and the memory, or the
source), for each way of building and calling them (batch first or not, one sequence, norm first or last,
activations, no bias, boolean, float and symbolic masks on the target and on the memory, the causal hints;
the decoder's layers, its final norm or none, and its detection of a causal mask; nn.Transformer's encoder
then decoder), in MX and SX; what torch refuses, refused in one line.

Exporting nn.TransformerDecoder or nn.Transformer was refused ("unsupported tensor attribute .is_nested,
inside torch.nn.TransformerDecoder, a layer the export does not map"); nn.TransformerDecoderLayer ran through
torch's forward, never checked against torch.
"""

from __future__ import annotations

import functools
import warnings

import casadi as ca
import pytest
import torch
import torch.nn.functional as F
from torch import nn

from tests.predictors.test_export import Wrap
from tests.predictors.test_export_attention import INF, randn
from tests.predictors.test_export_transformer import (
    BLOCKED,
    CAUSAL_BOOL,
    CAUSAL_FLOAT,
    PADDED,
    PER_HEAD,
    _drawn,
    assert_matches_torch,
    assert_refused_as_torch,
)


def layer(*args, **kwargs) -> nn.TransformerDecoderLayer:
    return _drawn(nn.TransformerDecoderLayer(*args, **kwargs))


def decoder(num_layers: int, norm: bool, **kwargs) -> nn.TransformerDecoder:
    inner = nn.TransformerDecoderLayer(4, 2, 8, **kwargs)
    return _drawn(nn.TransformerDecoder(inner, num_layers, norm=nn.LayerNorm(4) if norm else None))


def transformer(**kwargs) -> nn.Transformer:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torch's note that norm_first encoders take no nested tensors
        return _drawn(nn.Transformer(4, 2, 2, 2, 8, **kwargs))


# the target (T = 3) attends to a memory of S = 5: masks over the memory are (T, S) and (N, S)
MEMORY_PADDED = torch.tensor([[False, True, False, False, True], [False, False, False, True, False]])
MEMORY_BLOCKED = torch.tensor(
    [[False, True, False, False, False], [False] * 5, [True, False, False, True, False]]
)
MEMORY_CAUSAL = torch.ones(3, 5, dtype=torch.bool).tril().logical_not()  # torch's causal hint for T < S


def _call(**call):
    return lambda m, tgt, memory: m.dec(tgt, memory, **call)


def _pair(batch_first: bool = True, batched: bool = True):
    """A target of 3 steps and a memory of 5, batch of 2 (or one sequence)."""
    if not batched:
        return randn(3, 4), randn(5, 4)
    return (randn(2, 3, 4), randn(2, 5, 4)) if batch_first else (randn(3, 2, 4), randn(5, 2, 4))


# name: (module, forward of the wrapping module, inputs)
CASES = {
    "batch_first": (layer(4, 2, 8, batch_first=True), _call(), _pair()),
    "sequence_first_padded": (
        layer(4, 2, 8),
        _call(tgt_key_padding_mask=PADDED, memory_key_padding_mask=MEMORY_PADDED),
        _pair(False),
    ),
    "one_sequence": (
        layer(4, 2, 8, batch_first=True),
        _call(tgt_mask=BLOCKED, memory_key_padding_mask=MEMORY_PADDED[0], memory_mask=MEMORY_BLOCKED),
        _pair(batched=False),
    ),
    "norm_first_gelu": (
        layer(4, 2, 8, batch_first=True, norm_first=True, activation="gelu"),
        _call(),
        _pair(),
    ),
    "callable_and_module_activations": (
        layer(4, 2, 8, activation=nn.GELU(approximate="tanh"), norm_first=True),
        _call(memory_mask=MEMORY_BLOCKED),
        _pair(False),
    ),
    "any_callable": (
        layer(4, 2, 8, batch_first=True, activation=functools.partial(F.leaky_relu, negative_slope=0.2)),
        _call(),
        _pair(),
    ),
    "no_bias": (layer(4, 1, 6, batch_first=True, bias=False, dropout=0.0), _call(), _pair()),
    "bool_masks": (
        layer(4, 2, 8, batch_first=True),
        _call(
            tgt_mask=BLOCKED,
            tgt_key_padding_mask=PADDED,
            memory_mask=MEMORY_BLOCKED,
            memory_key_padding_mask=MEMORY_PADDED,
        ),
        _pair(),
    ),
    "float_masks": (
        layer(4, 2, 8, batch_first=True),
        _call(
            tgt_mask=PER_HEAD,
            memory_key_padding_mask=torch.zeros(2, 5, dtype=torch.float64).masked_fill(MEMORY_PADDED, -INF)
            + 0.3,
            memory_mask=torch.full((3, 5), -0.5, dtype=torch.float64),
        ),
        _pair(),
    ),
    "causal_hints": (
        layer(4, 2, 8, batch_first=True),
        _call(tgt_mask=CAUSAL_FLOAT, tgt_is_causal=True, memory_mask=MEMORY_CAUSAL, memory_is_causal=True),
        _pair(),
    ),
    "causal_hint_with_padding": (
        layer(4, 2, 8, norm_first=True),
        _call(tgt_mask=CAUSAL_BOOL, tgt_key_padding_mask=PADDED, tgt_is_causal=True),
        _pair(False),
    ),
    # masks given as inputs of the exported function, one of them float
    "symbolic_masks": (
        layer(4, 2, 8, batch_first=True),
        lambda m, tgt, memory, blocked, padded: m.dec(
            tgt, memory, tgt_mask=blocked, memory_key_padding_mask=padded
        ),
        (*_pair(), BLOCKED, torch.tensor([[0.0, -1.0, 0.5, -INF, 0.0], [-2.0, 0.0, 0.3, 0.0, 1.0]]).double()),
    ),
    "decoder_with_norm": (
        decoder(2, True, batch_first=True),
        _call(tgt_key_padding_mask=PADDED, memory_key_padding_mask=MEMORY_PADDED),
        _pair(),
    ),
    "decoder_sequence_first_without_norm": (
        decoder(3, False, dropout=0.3, activation="gelu"),
        _call(tgt_mask=BLOCKED, memory_mask=MEMORY_BLOCKED),
        _pair(False),
    ),
    # tgt_is_causal=None: torch compares tgt_mask with the causal one and, finding it, passes the hint on
    "decoder_detects_a_causal_mask": (
        decoder(2, True, batch_first=True),
        _call(tgt_mask=CAUSAL_FLOAT),
        _pair(),
    ),
    "decoder_causal_hint_with_padding": (
        decoder(2, False, batch_first=True, norm_first=True),
        _call(tgt_mask=CAUSAL_BOOL, tgt_key_padding_mask=PADDED, tgt_is_causal=True),
        _pair(),
    ),
    "decoder_one_sequence_symbolic_padding": (
        decoder(2, True, batch_first=True),
        lambda m, tgt, memory, padded: m.dec(tgt, memory, memory_key_padding_mask=padded),
        (*_pair(batched=False), MEMORY_PADDED[1]),
    ),
    # nn.Transformer(src, tgt): the source of 5 steps, the target of 3
    "transformer_batch_first": (
        transformer(batch_first=True),
        lambda m, src, tgt: m.dec(
            src,
            tgt,
            src_key_padding_mask=MEMORY_PADDED,
            tgt_mask=CAUSAL_FLOAT,
            memory_key_padding_mask=MEMORY_PADDED,
        ),
        (randn(2, 5, 4), randn(2, 3, 4)),
    ),
    "transformer_sequence_first_norm_first_gelu": (
        transformer(norm_first=True, activation="gelu"),
        lambda m, src, tgt: m.dec(src, tgt, src_mask=CAUSAL_BOOL, tgt_is_causal=False, memory_mask=BLOCKED),
        (randn(3, 2, 4), randn(3, 2, 4)),
    ),
    "transformer_one_sequence_symbolic_mask": (
        transformer(batch_first=True),
        lambda m, src, tgt, padded: m.dec(
            src, tgt, src_key_padding_mask=padded, memory_key_padding_mask=padded
        ),
        (randn(5, 4), randn(3, 4), MEMORY_PADDED[0]),
    ),
}

# Float masks other than 0 / -inf: torch's attention without gradients may read them as boolean (fast path)
ADDED_FLOAT_MASKS = {"float_masks", "symbolic_masks"}


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_transformer_decoder_matches_torch_in_values_and_jacobians(name, symbol):
    module, fn, inputs = CASES[name]
    wrapped = Wrap(fn, dec=module).double().eval()
    assert_matches_torch(wrapped, inputs, symbol, fast_path=name not in ADDED_FLOAT_MASKS)


@pytest.mark.parametrize(
    ("module", "call", "message"),
    [
        (
            lambda: layer(4, 2, 8, batch_first=True),
            lambda m, x: m.dec(x, x, tgt_mask=torch.zeros(3, 3, dtype=torch.int64)),
            r"nn\.TransformerDecoderLayer tgt_mask of dtype torch\.int64 \(bool or floating, as torch\)",
        ),
        (
            lambda: layer(4, 2, 8, batch_first=True),
            lambda m, x: m.dec(x, x, memory_key_padding_mask=torch.zeros(2, 3, dtype=torch.int32)),
            r"nn\.TransformerDecoderLayer memory_key_padding_mask of dtype torch\.int32",
        ),
        (
            lambda: layer(4, 2, 8, batch_first=True),
            lambda m, x: m.dec(x, x, tgt_is_causal=True),
            r"nn\.TransformerDecoderLayer with is_causal=True and no tgt_mask",
        ),
        (
            lambda: layer(4, 2, 8, batch_first=True),
            lambda m, x: m.dec(x, x, memory_is_causal=True),
            r"nn\.TransformerDecoderLayer with is_causal=True and no memory_mask",
        ),
        (
            lambda: layer(4, 2, 8, batch_first=True),
            lambda m, x: m.dec(x[..., :3], x),
            r"nn\.TransformerDecoderLayer tgt of shape \(2, 3, 3\) \(expected \(S, E\) or \(N, S, E\) with "
            r"E = d_model = 4, as torch\)",
        ),
        (
            lambda: layer(4, 2, 8, batch_first=True),
            lambda m, x: m.dec(x, x[:1]),
            r"nn\.TransformerDecoderLayer memory of shape \(1, 3, 4\) with tgt of shape \(2, 3, 4\)",
        ),
        (
            lambda: decoder(2, True, batch_first=True),
            lambda m, x: m.dec(x, x, tgt_is_causal=True),
            r"nn\.TransformerDecoder with is_causal=True and no tgt_mask",
        ),
        (
            lambda: transformer(batch_first=True),
            lambda m, x: m.dec(x, x[:1]),
            r"nn\.Transformer src of shape \(2, 3, 4\) and tgt of shape \(1, 3, 4\) \(the batch number of "
            r"src and tgt must be equal, as torch\)",
        ),
        (
            lambda: transformer(batch_first=True),
            lambda m, x: m.dec(x, x[..., :3]),
            r"nn\.Transformer src of shape \(2, 3, 4\) and tgt of shape \(2, 3, 3\) \(the feature number of "
            r"src and tgt must be equal to d_model = 4, as torch\)",
        ),
    ],
    ids=[
        "integer_mask",
        "integer_memory_padding",
        "causal_without_a_mask",
        "memory_causal_without_a_mask",
        "width",
        "memory_batch",
        "decoder_causal",
        "transformer_batch",
        "transformer_width",
    ],
)
def test_what_torch_refuses_is_refused_in_one_line_naming_the_argument(module, call, message):
    assert_refused_as_torch(Wrap(call, dec=module()), "dec", message)
