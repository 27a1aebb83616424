"""``nn.TransformerEncoderLayer``, ``nn.TransformerEncoder``, ``nn.TransformerDecoderLayer``,
``nn.TransformerDecoder`` and ``nn.Transformer``: torch's own arithmetic, laid out again on the layers'
submodules, without the choice of a path that comes first in torch's forward.

torch's forward asks ``src.is_nested`` and the masks' dtypes (``F._none_or_dtype`` refuses anything but a
``torch.Tensor``) to choose its inference fast path, which a symbolic tensor cannot answer. What is left is
the path torch takes with gradients (``_sa_block``, the decoder's ``_mha_block`` over the memory, and
``_ff_block`` around the norms), built here from
the layer's own submodules, each called as a module (``self_attn`` is ``nn.MultiheadAttention``'s CasADi
form, ``linear1``, ``norm1``, ``activation`` ... are mapped as anywhere else), so that a refusal names the
submodule it happens in (``encoder.layers.0.self_attn``).

Under ``torch.no_grad`` torch may take its fast path instead, whose output differs in three cases: a
sequence whose every key is padded is NaN there (here, as with gradients, the attention adds ``out_proj``'s
bias only), a float mask is read as boolean there (a nonzero entry leaves its key out, where torch with
gradients adds it), and ``nn.TransformerEncoder`` with ``enable_nested_tensor`` and a padding mask that pads
only the end of each sequence gives 0 at the padded positions (before its final norm), where the export, as
torch with gradients, computes them as any other. The decoder (``_get_seq_len`` asks ``tgt.is_nested``) and
``nn.Transformer`` take no fast path but ask alike, so they are laid out here too.
"""

from __future__ import annotations

from typing import Any

from torch import nn

from predictors.export.attention import check_masks
from predictors.export.errors import ExportError, current_module
from predictors.export.symbolic import lift


def _check_sequence(layer: str, name: str, x: Any, attention: nn.MultiheadAttention) -> None:
    """ExportError unless ``x`` is one sequence (S, E) or a batch of them, as ``attention`` takes it."""
    width, shape = attention.embed_dim, lift(x).shape_
    if len(shape) not in (2, 3) or shape[-1] != width:
        order = "(N, S, E)" if attention.batch_first else "(S, N, E)"
        raise ExportError(
            f"nn.{layer} {name} of shape {shape} (expected (S, E) or {order} with E = d_model = {width}, "
            "as torch)",
            current_module(),
        )


def _attend(
    attention: nn.MultiheadAttention,
    dropout: nn.Module,
    x: Any,
    keys: Any,
    mask: Any,
    padding: Any,
    causal: Any,
) -> Any:
    """A layer's attention block (torch's ``_sa_block``, the decoder's ``_mha_block``): ``attention`` of the
    queries ``x`` over ``keys`` (``x`` itself for self-attention, the memory for the decoder's second), its
    output through the block's ``dropout``."""
    out = attention(
        x, keys, keys, attn_mask=mask, key_padding_mask=padding, is_causal=causal, need_weights=False
    )[0]
    return dropout(out)


def _feed_forward(module: Any, dropout: nn.Module, x: Any) -> Any:
    """A layer's feed-forward block (torch's ``_ff_block``: an encoder or decoder layer's ``linear1``,
    ``activation``, ``dropout``, ``linear2``), its output through ``dropout``."""
    return dropout(module.linear2(module.dropout(module.activation(module.linear1(x)))))


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
    _check_sequence("TransformerEncoderLayer", "src", src, module.self_attn)

    def attend(x: Any) -> Any:
        return _attend(module.self_attn, module.dropout1, x, x, src_mask, src_key_padding_mask, is_causal)

    def feed_forward(x: Any) -> Any:
        return _feed_forward(module, module.dropout2, x)

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


def _check_memory(layer: str, tgt: Any, memory: Any, attention: nn.MultiheadAttention) -> None:
    """ExportError unless ``memory`` is a sequence batched as ``tgt`` (the same batch size), as torch's
    attention over it needs."""
    _check_sequence(layer, "memory", memory, attention)
    target, source = lift(tgt).shape_, lift(memory).shape_
    batch = 0 if attention.batch_first else 1
    if len(source) != len(target) or (len(target) == 3 and source[batch] != target[batch]):
        raise ExportError(
            f"nn.{layer} memory of shape {source} with tgt of shape {target} (expected both one sequence or "
            "both batches of the same size, as torch)",
            current_module(),
        )


def transformer_decoder_layer(
    module: nn.TransformerDecoderLayer,
    tgt: Any,
    memory: Any,
    tgt_mask: Any = None,
    memory_mask: Any = None,
    tgt_key_padding_mask: Any = None,
    memory_key_padding_mask: Any = None,
    tgt_is_causal: bool = False,
    memory_is_causal: bool = False,
) -> Any:
    """``module(tgt, memory, ...)`` in eval mode (its dropouts do nothing): self-attention over ``tgt``,
    attention over ``memory``, feed-forward, norm first or last, as torch's forward with gradients."""
    name = "TransformerDecoderLayer"
    check_masks(name, tgt_is_causal, tgt_mask=tgt_mask, tgt_key_padding_mask=tgt_key_padding_mask)
    check_masks(
        name, memory_is_causal, memory_mask=memory_mask, memory_key_padding_mask=memory_key_padding_mask
    )
    _check_sequence(name, "tgt", tgt, module.self_attn)
    _check_memory(name, tgt, memory, module.multihead_attn)

    def attend(x: Any) -> Any:
        return _attend(module.self_attn, module.dropout1, x, x, tgt_mask, tgt_key_padding_mask, tgt_is_causal)

    def recall(x: Any) -> Any:
        attention, dropout = module.multihead_attn, module.dropout2
        return _attend(attention, dropout, x, memory, memory_mask, memory_key_padding_mask, memory_is_causal)

    def feed_forward(x: Any) -> Any:
        return _feed_forward(module, module.dropout3, x)

    x = tgt
    if module.norm_first:
        x = x + attend(module.norm1(x))
        x = x + recall(module.norm2(x))
        return x + feed_forward(module.norm3(x))
    x = module.norm1(x + attend(x))
    x = module.norm2(x + recall(x))
    return module.norm3(x + feed_forward(x))


def transformer_decoder(
    module: nn.TransformerDecoder,
    tgt: Any,
    memory: Any,
    tgt_mask: Any = None,
    memory_mask: Any = None,
    tgt_key_padding_mask: Any = None,
    memory_key_padding_mask: Any = None,
    tgt_is_causal: bool | None = None,
    memory_is_causal: bool = False,
) -> Any:
    """``module(tgt, memory, ...)``: its layers in turn, each over the same memory, then its norm if any."""
    check_masks(
        "TransformerDecoder", tgt_is_causal, tgt_mask=tgt_mask, tgt_key_padding_mask=tgt_key_padding_mask
    )
    # as the encoder's: is_causal=None only chooses how torch applies the same tgt_mask, so False agrees
    causal = tgt_is_causal is True
    output = tgt
    for layer in module.layers:
        output = layer(
            output,
            memory,
            tgt_mask=tgt_mask,
            memory_mask=memory_mask,
            tgt_key_padding_mask=tgt_key_padding_mask,
            memory_key_padding_mask=memory_key_padding_mask,
            tgt_is_causal=causal,
            memory_is_causal=memory_is_causal,
        )
    return output if module.norm is None else module.norm(output)


def transformer(
    module: nn.Transformer,
    src: Any,
    tgt: Any,
    src_mask: Any = None,
    tgt_mask: Any = None,
    memory_mask: Any = None,
    src_key_padding_mask: Any = None,
    tgt_key_padding_mask: Any = None,
    memory_key_padding_mask: Any = None,
    src_is_causal: bool | None = None,
    tgt_is_causal: bool | None = None,
    memory_is_causal: bool = False,
) -> Any:
    """``module(src, tgt, ...)``: its encoder over ``src``, then its decoder over ``tgt`` and that memory,
    after torch's checks of the two sequences (refused in one line where torch raises)."""
    source, target = lift(src).shape_, lift(tgt).shape_
    batch = 0 if module.batch_first else 1
    if len(source) == 3 and (len(target) < 2 or source[batch] != target[batch]):
        raise ExportError(
            f"nn.Transformer src of shape {source} and tgt of shape {target} (the batch number of src and "
            "tgt must be equal, as torch)",
            current_module(),
        )
    if source[-1] != module.d_model or target[-1] != module.d_model:
        raise ExportError(
            f"nn.Transformer src of shape {source} and tgt of shape {target} (the feature number of src and "
            f"tgt must be equal to d_model = {module.d_model}, as torch)",
            current_module(),
        )
    memory = module.encoder(
        src, mask=src_mask, src_key_padding_mask=src_key_padding_mask, is_causal=src_is_causal
    )
    return module.decoder(
        tgt,
        memory,
        tgt_mask=tgt_mask,
        memory_mask=memory_mask,
        tgt_key_padding_mask=tgt_key_padding_mask,
        memory_key_padding_mask=memory_key_padding_mask,
        tgt_is_causal=tgt_is_causal,
        memory_is_causal=memory_is_causal,
    )
