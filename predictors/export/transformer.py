"""``nn.TransformerEncoderLayer`` and ``nn.TransformerEncoder``: torch's own arithmetic, laid out again on the
layer's submodules, without the choice of a path that comes first in torch's forward.

torch's forward asks ``src.is_nested`` and the masks' dtypes (``F._none_or_dtype`` refuses anything but a
``torch.Tensor``) to choose its inference fast path, which a symbolic tensor cannot answer. What is left is
the path torch takes with gradients (``_sa_block`` and ``_ff_block`` around the two norms), built here from
the layer's own submodules, each called as a module (``self_attn`` is ``nn.MultiheadAttention``'s CasADi
form, ``linear1``, ``norm1``, ``activation`` ... are mapped as anywhere else), so that a refusal names the
submodule it happens in (``encoder.layers.0.self_attn``).

Under ``torch.no_grad`` torch may take its fast path instead, whose output differs in three cases: a
sequence whose every key is padded is NaN there (here, as with gradients, the attention adds ``out_proj``'s
bias only), a float mask is read as boolean there (a nonzero entry leaves its key out, where torch with
gradients adds it), and ``nn.TransformerEncoder`` with ``enable_nested_tensor`` and a padding mask that pads
only the end of each sequence gives 0 at the padded positions (before its final norm), where the export, as
torch with gradients, computes them as any other.
"""

from __future__ import annotations

from typing import Any

from torch import nn

from predictors.export.attention import check_masks
from predictors.export.errors import ExportError, current_module
from predictors.export.symbolic import lift


def transformer_encoder_layer(
    module: nn.TransformerEncoderLayer,
    src: Any,
    src_mask: Any = None,
    src_key_padding_mask: Any = None,
    is_causal: bool = False,
) -> Any:
    """``module(src, src_mask, src_key_padding_mask, is_causal)`` in eval mode (its dropouts do nothing),
    batch first or not, one sequence or a batch, norm first or last."""
    check_masks(
        "TransformerEncoderLayer", is_causal, src_mask=src_mask, src_key_padding_mask=src_key_padding_mask
    )
    width = module.self_attn.embed_dim
    shape = lift(src).shape_
    if len(shape) not in (2, 3) or shape[-1] != width:
        order = "(N, S, E)" if module.self_attn.batch_first else "(S, N, E)"
        raise ExportError(
            f"nn.TransformerEncoderLayer src of shape {shape} (expected (S, E) or {order} with E = d_model = "
            f"{width}, as torch)",
            current_module(),
        )

    def attend(x: Any) -> Any:
        out = module.self_attn(
            x,
            x,
            x,
            attn_mask=src_mask,
            key_padding_mask=src_key_padding_mask,
            need_weights=False,
            is_causal=is_causal,
        )[0]
        return module.dropout1(out)

    def feed_forward(x: Any) -> Any:
        return module.dropout2(module.linear2(module.dropout(module.activation(module.linear1(x)))))

    x = src
    if module.norm_first:
        x = x + attend(module.norm1(x))
        return x + feed_forward(module.norm2(x))
    x = module.norm1(x + attend(x))
    return module.norm2(x + feed_forward(x))


def transformer_encoder(
    module: nn.TransformerEncoder,
    src: Any,
    mask: Any = None,
    src_key_padding_mask: Any = None,
    is_causal: bool | None = None,
) -> Any:
    """``module(src, mask, src_key_padding_mask, is_causal)``: its layers in turn, then its norm if any."""
    check_masks("TransformerEncoder", is_causal, mask=mask, src_key_padding_mask=src_key_padding_mask)
    # is_causal=None asks torch to compare the mask with the causal one (a symbolic mask cannot be compared);
    # what it finds only chooses how torch applies that same mask, so False gives the same values.
    causal = is_causal is True
    output = src
    for layer in module.layers:
        output = layer(output, src_mask=mask, src_key_padding_mask=src_key_padding_mask, is_causal=causal)
    return output if module.norm is None else module.norm(output)
