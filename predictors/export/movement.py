"""Data movement: reshapes, permutes, slicing, cat and the like, each a gather whose indices numpy computes
(``predictors.export.symbolic.gather_like``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np
import torch

from predictors.export.errors import ExportError, current_module
from predictors.export.symbolic import (
    SymTensor,
    arange_of,
    broadcast_to,
    gather_like,
    lift,
)


def normal_dim(dim: int, ndim: int) -> int:
    """``dim`` of a tensor of ``ndim`` dims counted from the front; out of torch's range (a 0-d tensor takes
    -1 and 0) torch's IndexError, where a wrong dim was otherwise taken as no dim or another one."""
    bound = max(ndim, 1)
    if not -bound <= dim < bound:
        raise IndexError(
            f"Dimension out of range (expected to be in range of [{-bound}, {bound - 1}], but got {dim})"
        )
    return dim + ndim if dim < 0 else dim


def shape_args(args: tuple) -> tuple[int, ...]:
    """``reshape(2, 3)`` and ``reshape((2, 3))`` alike."""
    if len(args) == 1 and isinstance(args[0], (tuple, list, torch.Size)):
        args = tuple(args[0])
    return tuple(int(a) for a in args)


# ------------------------------------------------------------------------------------------- data movement
def reshape(x, *shape):
    x = lift(x)
    target = list(shape_args(shape))
    if -1 in target:
        known = math.prod(s for s in target if s != -1)
        target[target.index(-1)] = x.numel() // known if known else 0
    target_t = tuple(target)
    if math.prod(target_t) != x.numel():
        raise ExportError(f"reshape of {x.shape_} to {tuple(shape)}", current_module())
    if target_t and x.shape_ and target_t[-1] == x.shape_[-1]:
        return SymTensor(x.m, target_t, x.is_bool)  # the same row-major 2-D view
    return SymTensor.from_flat(x.flat(), target_t, x.is_bool)


def flatten(x, start_dim=0, end_dim=-1):
    x = lift(x)
    if not x.shape_:
        return reshape(x, 1)
    start, end = normal_dim(start_dim, x.ndim), normal_dim(end_dim, x.ndim)
    shape = x.shape_[:start] + (math.prod(x.shape_[start : end + 1]),) + x.shape_[end + 1 :]
    return reshape(x, shape)


def unsqueeze(x, dim):
    x = lift(x)
    dim = normal_dim(dim, x.ndim + 1)
    return reshape(x, x.shape_[:dim] + (1,) + x.shape_[dim:])


def squeeze(x, dim=None):
    x = lift(x)
    if dim is None:
        dims = {i for i, s in enumerate(x.shape_) if s == 1}
    else:
        dims = {normal_dim(d, x.ndim) for d in (dim if isinstance(dim, (tuple, list)) else (dim,))}
        dims = {d for d in dims if x.shape_[d] == 1}
    return reshape(x, tuple(s for i, s in enumerate(x.shape_) if i not in dims))


def permute(x, *dims):
    x = lift(x)
    order = tuple(normal_dim(d, x.ndim) for d in shape_args(dims))
    return gather_like(x, np.transpose(arange_of(x), order))


def transpose(x, dim0, dim1):
    x = lift(x)
    order = list(range(x.ndim))
    a, b = normal_dim(dim0, x.ndim), normal_dim(dim1, x.ndim)
    order[a], order[b] = order[b], order[a]
    return permute(x, tuple(order))


def expand(x, *sizes):
    x = lift(x)
    target = shape_args(sizes)
    padded = (1,) * (len(target) - x.ndim) + x.shape_
    shape = tuple(p if t == -1 else t for p, t in zip(padded, target, strict=True))
    return broadcast_to(reshape(x, padded), shape)


def expand_as(x, other):
    return expand(x, tuple(other.shape))


def repeat(x, *sizes):
    x = lift(x)
    return gather_like(x, np.tile(arange_of(x), shape_args(sizes)))


def _index_key(key: Any) -> Any:
    """A torch index as a numpy one; a symbolic index is a value-dependent gather, which cannot export."""
    if isinstance(key, tuple):
        return tuple(_index_key(k) for k in key)
    if isinstance(key, SymTensor):
        raise ExportError("indexing with a symbolic tensor (a value-dependent gather)", current_module())
    if isinstance(key, torch.Tensor):
        return key.detach().cpu().numpy()
    if isinstance(key, list):
        return np.asarray(key)
    return key


def getitem(x, key):
    x = lift(x)
    return gather_like(x, arange_of(x)[_index_key(key)])


def select(x, dim, index):
    x = lift(x)
    key = (slice(None),) * normal_dim(dim, x.ndim) + (index,)
    return getitem(x, key)


def narrow(x, dim, start, length):
    x = lift(x)
    key = (slice(None),) * normal_dim(dim, x.ndim) + (slice(start, start + length),)
    return getitem(x, key)


def cat(tensors: Sequence[Any], dim=0, *, out=None):
    parts = [lift(t) for t in tensors if not (isinstance(t, torch.Tensor) and t.numel() == 0 and t.ndim == 1)]
    ndim = parts[0].ndim
    dim = normal_dim(dim, ndim)
    shape = list(parts[0].shape_)
    shape[dim] = sum(p.shape_[dim] for p in parts)
    is_bool = all(p.is_bool for p in parts)
    if dim == ndim - 1:  # along the columns of the 2-D views
        return SymTensor(ca.horzcat(*[p.m for p in parts]), tuple(shape), is_bool)
    if math.prod(shape[:dim]) == 1:  # stacking rows
        return SymTensor(ca.vertcat(*[p.m for p in parts]), tuple(shape), is_bool)
    offsets = np.cumsum([0] + [p.numel() for p in parts])
    index = np.concatenate([arange_of(p) + o for p, o in zip(parts, offsets, strict=False)], axis=dim)
    joined = SymTensor.from_flat(ca.vertcat(*[p.flat() for p in parts]), (int(offsets[-1]),), is_bool)
    return gather_like(joined, index)


def stack(tensors: Sequence[Any], dim=0, *, out=None):
    parts = [lift(t) for t in tensors]
    dim = normal_dim(dim, parts[0].ndim + 1)
    return cat([unsqueeze(p, dim) for p in parts], dim)


def chunk(x, chunks, dim=0):
    x = lift(x)
    size = math.ceil(x.shape_[normal_dim(dim, x.ndim)] / chunks)
    return split(x, size, dim)


def split(x, size, dim=0):
    x = lift(x)
    dim = normal_dim(dim, x.ndim)
    total = x.shape_[dim]
    sizes = (
        list(size)
        if isinstance(size, (list, tuple))
        else [min(size, total - s) for s in range(0, total, size)]
    )
    starts = np.cumsum([0] + sizes[:-1])
    return tuple(narrow(x, dim, int(s), n) for s, n in zip(starts, sizes, strict=True))


def unbind(x, dim=0):
    x = lift(x)
    return tuple(select(x, dim, i) for i in range(x.shape_[normal_dim(dim, x.ndim)]))
