"""Attention: ``F.scaled_dot_product_attention`` and ``nn.MultiheadAttention``, one softmax of scores.

``attention_weights`` is the one place scores are formed, masked and normalised; the scaled dot-product
attention multiplies them by the values, and the multi-head layer does so after its projections, head split
and masks, as ``torch.nn.functional.multi_head_attention_forward`` arranges them (sequence first, heads
folded into the batch: ``(N * H, L, head_dim)``).
"""

from __future__ import annotations

import math
from typing import Any

import torch
from torch import nn

from predictors.export.elementwise import add, operand, where
from predictors.export.errors import ExportError, current_module
from predictors.export.linalg import linear, matmul, mean, softmax_rows
from predictors.export.movement import cat, expand, reshape, squeeze, transpose, unsqueeze
from predictors.export.symbolic import SymTensor, lift


# ------------------------------------------------------------------------------- scaled dot-product attention
def attention_weights(
    query, key, attn_mask=None, is_causal=False, scale=None, *, empty_rows_zero=True
) -> SymTensor:
    """softmax(q k^T * scale + mask) over the keys, torch's masks: a boolean one keeps its True entries, a
    float one is added (its -inf entries are left out). A query whose every key is left out gets weights 0
    with ``empty_rows_zero`` (torch's attention, its _safe_softmax), else NaN (a plain softmax, as
    nn.MultiheadAttention's when it returns its weights)."""
    q, k = lift(query), lift(key)
    factor = 1 / math.sqrt(q.shape_[-1]) if scale is None else scale
    scores = matmul(q, transpose(k, -2, -1))
    scores = SymTensor(scores.m * factor, scores.shape_)
    mask = None
    if is_causal:
        length, source = scores.shape_[-2:]
        attn_mask = torch.ones(length, source, dtype=torch.bool).tril()
    if attn_mask is not None:
        m = lift(attn_mask)
        if m.is_bool:
            mask = operand(m, scores.shape_)
        else:
            scores = add(scores, m)
            mask = scores.m != -math.inf  # torch's attention masks by -inf, so these are its masked keys
    return SymTensor(softmax_rows(scores.m, mask, empty_rows_zero=empty_rows_zero), scores.shape_)


def scaled_dot_product_attention(
    query, key, value, attn_mask=None, dropout_p=0.0, is_causal=False, scale=None, enable_gqa=False
):
    if dropout_p:
        raise ExportError("scaled_dot_product_attention with dropout_p > 0", current_module())
    return matmul(attention_weights(query, key, attn_mask, is_causal, scale), lift(value))


# -------------------------------------------------------------------------------------- nn.MultiheadAttention
def _expect(ok: bool, what: str, shape: tuple[int, ...], expected: str) -> None:
    if not ok:
        raise ExportError(
            f"nn.MultiheadAttention {what} of shape {shape} (expected {expected}, as torch)", current_module()
        )


def _check_shapes(module: nn.MultiheadAttention, q: SymTensor, k: SymTensor, v: SymTensor) -> bool:
    """Whether the call is batched; shapes torch would refuse (with an AssertionError) refused here."""
    e, batch = module.embed_dim, "(L, N, E)" if not module.batch_first else "(N, L, E)"
    _expect(q.ndim in (2, 3) and q.shape_[-1] == e, "query", q.shape_, f"(L, {e}) or {batch} with E = {e}")
    for what, x, width in (("key", k, module.kdim), ("value", v, module.vdim)):
        _expect(x.ndim == q.ndim and x.shape_[-1] == width, what, x.shape_, f"{q.ndim}-D, last dim {width}")
    _expect(k.shape_[:-1] == v.shape_[:-1], "value", v.shape_, f"key's leading dims {k.shape_[:-1]}")
    return q.ndim == 3


def check_masks(layer: str, is_causal: bool | None, **masks: Any) -> None:
    """ExportError where torch refuses the masks of ``nn.{layer}`` (the first of ``masks`` is the one the
    causal hint needs): a mask is boolean (True left out) or floating (added), as torch's F._canonical_mask
    takes it, and ``is_causal`` is a hint about a mask given, not a mask (torch's attention raises alike)."""
    for name, mask in masks.items():
        if isinstance(mask, torch.Tensor) and not (mask.dtype == torch.bool or mask.is_floating_point()):
            raise ExportError(
                f"nn.{layer} {name} of dtype {mask.dtype} (bool or floating, as torch)", current_module()
            )
    name, mask = next(iter(masks.items()))
    if is_causal and mask is None:
        raise ExportError(
            f"nn.{layer} with is_causal=True and no {name} (torch needs the mask with the hint)",
            current_module(),
        )


def _additive(mask: Any, name: str, shapes: tuple[tuple[int, ...], ...]) -> SymTensor | None:
    """``mask`` as the float mask torch adds to the scores (its _canonical_mask): a boolean one's True
    entries (left out) -inf, its False ones 0; a float one as it is."""
    if mask is None:
        return None
    m = lift(mask)
    _expect(m.shape_ in shapes, name, m.shape_, " or ".join(str(s) for s in shapes))
    return where(m, -math.inf, 0.0) if m.is_bool else m


def _pad(mask: SymTensor | None) -> SymTensor | None:
    """One more key, never masked (torch pads with 0 for bias_k and add_zero_attn)."""
    if mask is None:
        return None
    return cat([mask, torch.zeros(mask.shape_[:-1] + (1,), dtype=torch.float64)], -1)


def _in_projection(module: nn.MultiheadAttention, q, k, v) -> tuple[SymTensor, SymTensor, SymTensor]:
    """The query, key and value projections: packed in in_proj_weight, or q/k/v_proj_weight (kdim or vdim
    other than embed_dim); in_proj_bias, when there is one, packed either way."""
    if module._qkv_same_embed_dim:
        weights = module.in_proj_weight.chunk(3)
    else:
        weights = (module.q_proj_weight, module.k_proj_weight, module.v_proj_weight)
    biases = (None,) * 3 if module.in_proj_bias is None else module.in_proj_bias.chunk(3)
    return tuple(linear(x, w, b) for x, w, b in zip((q, k, v), weights, biases, strict=True))  # type: ignore[return-value]


def _split_heads(x: SymTensor, batch: int, heads: int) -> SymTensor:
    """(S, N, E) to (N * H, S, E / H)."""
    length, _, width = x.shape_
    return transpose(reshape(x, (length, batch * heads, width // heads)), 0, 1)


def multihead_attention(
    module: nn.MultiheadAttention,
    query: Any,
    key: Any,
    value: Any,
    key_padding_mask: Any = None,
    need_weights: bool = True,
    attn_mask: Any = None,
    average_attn_weights: bool = True,
    is_causal: bool = False,
) -> tuple[SymTensor, SymTensor | None]:
    """``module(query, key, value, ...)``: (output, weights or None), as torch's
    ``F.multi_head_attention_forward``. ``module`` runs in eval mode (the export sets it), where torch's
    dropout does nothing. A query whose every key is masked gives NaN with ``need_weights`` (a plain
    softmax), else weights 0 (torch's scaled dot-product attention), as torch computes them with gradients;
    its inference fast path gives NaN in both."""
    q, k, v = lift(query), lift(key), lift(value)
    batched = _check_shapes(module, q, k, v)
    if batched and module.batch_first:
        q, k, v = (transpose(x, 0, 1) for x in (q, k, v))
    elif not batched:  # one sequence: a batch of one, as torch
        q, k, v = (unsqueeze(x, 1) for x in (q, k, v))
        key_padding_mask = None if key_padding_mask is None else unsqueeze(lift(key_padding_mask), 0)
    (length, batch, width), source, heads = q.shape_, k.shape_[0], module.num_heads
    check_masks("MultiheadAttention", is_causal, attn_mask=attn_mask, key_padding_mask=key_padding_mask)
    # torch drops a causal hint's mask for its own only without a padding mask or weights, and keeps it else
    causal = is_causal and key_padding_mask is None and not need_weights
    padding = _additive(key_padding_mask, "key_padding_mask", ((batch, source),))
    mask = (
        None
        if causal
        else _additive(attn_mask, "attn_mask", ((length, source), (batch * heads, length, source)))
    )
    q, k, v = _in_projection(module, q, k, v)
    if module.bias_k is not None and module.bias_v is not None:  # add_bias_kv: one learnt key and value more
        k = cat([k, module.bias_k.repeat(1, batch, 1)])
        v = cat([v, module.bias_v.repeat(1, batch, 1)])
        mask, padding = _pad(mask), _pad(padding)
    q, k, v = (_split_heads(x, batch, heads) for x in (q, k, v))
    if module.add_zero_attn:  # one key and value of zeros more, per head
        zeros = torch.zeros(batch * heads, 1, width // heads, dtype=torch.float64)
        k, v = cat([k, zeros], 1), cat([v, zeros], 1)
        mask, padding = _pad(mask), _pad(padding)
    if padding is not None:
        keys = k.shape_[1]
        padding = reshape(
            expand(reshape(padding, (batch, 1, 1, keys)), (batch, heads, 1, keys)), (-1, 1, keys)
        )
        mask = padding if mask is None else add(mask, padding)
    weights = attention_weights(q, k, mask, causal, empty_rows_zero=not need_weights)
    out = reshape(transpose(matmul(weights, v), 0, 1), (length * batch, width))
    out = reshape(linear(out, module.out_proj.weight, module.out_proj.bias), (length, batch, width))
    if not batched:
        out = squeeze(out, 1)
    elif module.batch_first:
        out = transpose(out, 0, 1)
    if not need_weights:
        return out, None
    per_head = reshape(weights, (batch, heads, length, k.shape_[1]))
    averaged = mean(per_head, 1) if average_attn_weights else per_head
    return out, averaged if batched else squeeze(averaged, 0)
