"""Network layers (layer norm, attention, dropout) and the constants torch code creates."""

from __future__ import annotations

import math
from collections.abc import Callable

import casadi as ca
import torch

from predictors.export.elementwise import add, operand
from predictors.export.errors import ExportError, current_module
from predictors.export.linalg import matmul, softmax_rows
from predictors.export.movement import reshape, shape_args, transpose
from predictors.export.symbolic import (
    SymTensor,
    as_float,
    lift,
)


# ------------------------------------------------------------------------------------------------- networks
def layer_norm(x, normalized_shape, weight=None, bias=None, eps=1e-5):
    x = as_float(lift(x))
    width = math.prod(normalized_shape)
    flat = reshape(x, x.shape_[: x.ndim - len(normalized_shape)] + (width,))
    m = flat.m
    centred = m - ca.repmat(ca.sum2(m) / width, 1, width)
    variance = ca.sum2(centred**2) / width  # biased, as torch
    y = centred / ca.repmat(ca.sqrt(variance + eps), 1, width)
    if weight is not None:
        y = y * ca.repmat(lift(reshape(lift(weight), (1, width))).m, y.shape[0], 1)
    if bias is not None:
        y = y + ca.repmat(lift(reshape(lift(bias), (1, width))).m, y.shape[0], 1)
    return reshape(SymTensor(y, flat.shape_), x.shape_)


def scaled_dot_product_attention(
    query, key, value, attn_mask=None, dropout_p=0.0, is_causal=False, scale=None, enable_gqa=False
):
    if dropout_p:
        raise ExportError("scaled_dot_product_attention with dropout_p > 0", current_module())
    q, k, v = lift(query), lift(key), lift(value)
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
    # torch gives a row with every key masked 0 (its _safe_softmax), not softmax's NaN
    weights = SymTensor(softmax_rows(scores.m, mask, empty_rows_zero=True), scores.shape_)
    return matmul(weights, v)


def dropout(x, p=0.5, training=False, inplace=False):
    if training and p > 0:
        raise ExportError("dropout in training mode (export a net in eval mode)", current_module())
    return x


# -------------------------------------------------------------------------------------------- constants
def zeros_like(x, *args, dtype=None, **kwargs):
    return torch.zeros(tuple(x.shape), dtype=torch.bool if dtype == torch.bool else torch.float64)


def ones_like(x, *args, dtype=None, **kwargs):
    return torch.ones(tuple(x.shape), dtype=torch.bool if dtype == torch.bool else torch.float64)


def full_like(x, fill_value, *args, dtype=None, **kwargs):
    return torch.full(tuple(x.shape), fill_value, dtype=torch.float64)


def new_constant(maker: Callable[..., torch.Tensor]) -> Callable[..., torch.Tensor]:
    def make(x, *size, dtype=None, device=None, requires_grad=False, **kwargs):
        dtype = torch.bool if dtype == torch.bool else torch.float64
        return maker(shape_args(size), dtype=dtype)

    return make


def new_full(x, size, fill_value, *, dtype=None, **kwargs):
    return torch.full(shape_args((size,)), fill_value, dtype=torch.float64)
