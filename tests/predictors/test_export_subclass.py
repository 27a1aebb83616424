"""A user's subclass of a layer the export maps (nn.TransformerEncoderLayer, nn.MultiheadAttention ...):
mapped as its torch layer where it keeps all of torch's forward, its own forward run where it has one, and a
refusal met there naming the torch layer it derives from.

A subclass with its own forward was refused as "unsupported tensor attribute .is_nested (in module
'block')", which named neither the layer nor what to do; one that only added attributes ran torch's forward
and was refused alike, though the export computes that forward.
"""

from __future__ import annotations

import casadi as ca
import pytest
import torch
from torch import nn

from predictors.export import ExportError
from tests.predictors.test_export import Wrap
from tests.predictors.test_export_attention import _export, randn
from tests.predictors.test_export_transformer import _drawn, assert_matches_torch


class TaggedEncoderLayer(nn.TransformerEncoderLayer):
    """Only an attribute more: torch's forward runs."""

    def __init__(self, *args, tag: str = "", **kwargs):
        super().__init__(*args, **kwargs)
        self.tag = tag


class TaggedAttention(nn.MultiheadAttention):
    tag = "attention"


class TaggedEncoder(nn.TransformerEncoder):
    pass


class ScaledEncoderLayer(nn.TransformerEncoderLayer):
    def forward(self, src, *args, **kwargs):
        return super().forward(2 * src, *args, **kwargs)


class OwnBlockEncoderLayer(nn.TransformerEncoderLayer):
    """torch's forward, but calling an attention block of its own."""

    def _sa_block(self, x, attn_mask, key_padding_mask, is_causal=False):
        return super()._sa_block(x, attn_mask, key_padding_mask, is_causal) * 0.5


class ScaledAttention(nn.MultiheadAttention):
    def forward(self, query, key, value, *args, **kwargs):
        return super().forward(query, key, value * 2, *args, **kwargs)


class ScaledDecoder(nn.TransformerDecoder):
    def forward(self, tgt, memory, *args, **kwargs):
        return super().forward(tgt, 2 * memory, *args, **kwargs)


class ScaledCell(nn.LSTMCell):
    def forward(self, input, hx=None):  # noqa: A002 (torch's name)
        return super().forward(2 * input, hx)


class PlainEncoderLayer(nn.TransformerEncoderLayer):
    """Its own forward in supported operations (no fast path): exported as written."""

    def forward(self, src, *args, **kwargs):
        x = self.norm1(src + self.self_attn(src, src, src, need_weights=False)[0])
        return self.norm2(x + self.linear2(torch.relu(self.linear1(x))))


def _layer(cls, **kwargs):
    return _drawn(cls(4, 2, 8, batch_first=True, **kwargs))


# name: (module, forward of the wrapping module)
MAPPED_AS_TORCH = {
    "encoder_layer": (_layer(TaggedEncoderLayer, tag="t"), lambda m, x: m.block(x)),
    "attention": (
        _drawn(TaggedAttention(4, 2, batch_first=True)),
        lambda m, x: m.block(x, x, x, need_weights=False)[0],
    ),
    "encoder": (
        _drawn(TaggedEncoder(_layer(TaggedEncoderLayer), 2, enable_nested_tensor=False)),
        lambda m, x: m.block(x),
    ),
    "own_forward_in_supported_operations": (_layer(PlainEncoderLayer), lambda m, x: m.block(x)),
}


@pytest.mark.parametrize("symbol", [ca.MX, ca.SX], ids=["MX", "SX"])
@pytest.mark.parametrize("name", sorted(MAPPED_AS_TORCH))
def test_a_subclass_that_keeps_torchs_forward_exports_as_torch_computes_it(name, symbol):
    module, fn = MAPPED_AS_TORCH[name]
    wrapped = Wrap(fn, block=module).double().eval()
    assert_matches_torch(wrapped, (randn(2, 3, 4),), symbol, fast_path=False)


@pytest.mark.parametrize(
    ("module", "fn", "inputs", "layer", "own"),
    [
        (
            _layer(ScaledEncoderLayer),
            lambda m, x: m.block(x),
            (2, 3, 4),
            "TransformerEncoderLayer",
            "forward",
        ),
        (
            _layer(OwnBlockEncoderLayer),
            lambda m, x: m.block(x),
            (2, 3, 4),
            "TransformerEncoderLayer",
            "_sa_block",
        ),
        (
            ScaledAttention(4, 2, batch_first=True),
            lambda m, x: m.block(x, x, x)[0],
            (2, 3, 4),
            "MultiheadAttention",
            "forward",
        ),
        (
            ScaledDecoder(nn.TransformerDecoderLayer(4, 2, 8, batch_first=True), 1),
            lambda m, x: m.block(x, x),
            (2, 3, 4),
            "TransformerDecoder",
            "forward",
        ),
        (ScaledCell(4, 3), lambda m, x: m.block(x)[0], (2, 4), "LSTMCell", "forward"),
    ],
    ids=["encoder_layer", "encoder_layer_block", "attention", "decoder", "lstm_cell"],
)
def test_a_subclass_with_its_own_forward_is_refused_naming_the_torch_layer(module, fn, inputs, layer, own):
    wrapped = Wrap(fn, block=module).double().eval()
    with pytest.raises(ExportError) as info:
        _export(wrapped, (randn(*inputs),))
    name = type(module).__qualname__
    message = str(info.value)
    assert (
        f", inside {name}, a subclass of torch.nn.{layer} with its own {own} (the export maps torch's own "
        f"layer only) (in module 'block'); keep torch.nn.{layer} itself as a submodule" in message
    ), message
    assert message.endswith("listed in docs/extending.md, section 1") and "\n" not in message
