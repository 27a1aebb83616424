"""Network layers (layer norm, dropout; attention is ``predictors.export.attention``) and the constants torch
code creates."""

from __future__ import annotations

import math
from collections.abc import Callable

import casadi as ca
import torch

from predictors.export.errors import ExportError, current_module
from predictors.export.movement import reshape, shape_args
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
