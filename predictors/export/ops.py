"""The torch operations the exporter maps to CasADi, each in the layout of ``predictors.export.symbolic``.

Every supported operation is a key of ``HANDLERS`` (functions, ``torch.Tensor`` operators) or ``METHODS``
(``x.reshape(...)``); anything else raises ``ExportError`` naming the operation and the module. Pure data
movement goes through ``gather_like`` on numpy's own index arithmetic; arithmetic is whole-matrix CasADi.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import casadi as ca
import numpy as np
import torch
import torch.nn.functional as F

from predictors.export.errors import ExportError, current_module
from predictors.export.symbolic import (
    HANDLERS,
    METHODS,
    SymTensor,
    arange_of,
    as_float,
    broadcast_to,
    constant,
    gather_like,
    lift,
    rows_cols,
)


def _dims(dim: int, ndim: int) -> int:
    return dim + ndim if dim < 0 else dim


def _shape_args(args: tuple) -> tuple[int, ...]:
    """``reshape(2, 3)`` and ``reshape((2, 3))`` alike."""
    if len(args) == 1 and isinstance(args[0], (tuple, list, torch.Size)):
        args = tuple(args[0])
    return tuple(int(a) for a in args)


# ----------------------------------------------------------------------------------------------- elementwise
def _operand(x: SymTensor, shape: tuple[int, ...]) -> Any:
    """``x.m`` brought to ``shape``: a scalar stays one, a row or column is repeated, the rest gathered."""
    if x.numel() == 1 or x.shape_ == shape:
        return x.m
    rows, cols = rows_cols(shape)
    padded = (1,) * (len(shape) - len(x.shape_)) + x.shape_
    if padded[-1] == cols and math.prod(padded[:-1]) == 1:
        return ca.repmat(x.m, rows, 1)
    if padded[:-1] == shape[:-1] and padded[-1] == 1:
        return ca.repmat(x.m, 1, cols)
    return broadcast_to(x, shape).m


def _is_constant(value: Any, number: float) -> bool:
    if isinstance(value, SymTensor):
        return False
    array = constant(value)
    return bool(array.size) and bool((array == number).all())


def binary(op: Callable[[Any, Any], Any], a: Any, b: Any, *, is_bool: bool = False) -> SymTensor:
    x, y = lift(a), lift(b)
    shape = tuple(np.broadcast_shapes(x.shape_, y.shape_))
    return SymTensor(op(_operand(x, shape), _operand(y, shape)), shape, is_bool)


def add(a, b, *, alpha=1):
    if alpha != 1:
        b = mul(b, alpha)
    for sym, other in ((a, b), (b, a)):  # x + 0: no node (masks of ones and zeros are common)
        if isinstance(sym, SymTensor) and _is_constant(other, 0.0):
            if tuple(np.broadcast_shapes(sym.shape_, tuple(np.shape(constant(other))))) == sym.shape_:
                return as_float(sym)
    return binary(lambda p, q: p + q, a, b)


def sub(a, b, *, alpha=1):
    return add(a, mul(b, -alpha) if isinstance(b, SymTensor) else -alpha * constant(b))


def mul(a, b):
    for sym, other in ((a, b), (b, a)):  # x * 1: no node
        if isinstance(sym, SymTensor) and _is_constant(other, 1.0):
            if tuple(np.broadcast_shapes(sym.shape_, tuple(np.shape(constant(other))))) == sym.shape_:
                return as_float(sym)
    return binary(lambda p, q: p * q, a, b)


def div(a, b, *, rounding_mode=None):
    if rounding_mode is not None:
        raise ExportError(f"division with rounding_mode={rounding_mode!r}", current_module())
    return binary(lambda p, q: p / q, a, b)


def power(a, b):
    return binary(lambda p, q: p**q, a, b)


def where(condition, a, b):
    c, x, y = lift(condition), lift(a), lift(b)
    shape = tuple(np.broadcast_shapes(c.shape_, x.shape_, y.shape_))
    if not isinstance(condition, SymTensor):  # a constant mask, all True or all False, needs no node
        mask = constant(condition).astype(bool)
        if mask.all():
            return broadcast_to(x, shape)
        if not mask.any():
            return broadcast_to(y, shape)
    # if_else, not c * a + (1 - c) * b: an infinite value in the branch not taken must not give NaN.
    return SymTensor(
        ca.if_else(_operand(c, shape), _operand(x, shape), _operand(y, shape), False), shape, x.is_bool
    )


def unary(op: Callable[[Any], Any]) -> Callable[..., SymTensor]:
    def apply(x, *args, **kwargs):
        x = lift(x)
        return SymTensor(op(x.m), x.shape_)

    return apply


def sigmoid(m):
    # exp(-x) overflows to inf for x << 0, and 1 / (1 + inf) is the correct limit 0.
    return 1 / (1 + ca.exp(-m))


def gelu(x, approximate="none"):
    x = lift(x)
    if approximate == "tanh":
        inner = math.sqrt(2 / math.pi) * (x.m + 0.044715 * x.m**3)
        return SymTensor(0.5 * x.m * (1 + ca.tanh(inner)), x.shape_)
    return SymTensor(0.5 * x.m * (1 + ca.erf(x.m / math.sqrt(2))), x.shape_)


def softplus(x, beta=1.0, threshold=20.0):
    x = lift(x)
    scaled = beta * x.m
    # torch reverts to the identity above the threshold, where log1p(exp) would overflow
    return SymTensor(ca.if_else(scaled > threshold, x.m, ca.log1p(ca.exp(scaled)) / beta, False), x.shape_)


def leaky_relu(x, negative_slope=0.01, inplace=False):
    x = lift(x)
    return SymTensor(ca.fmax(x.m, 0) + negative_slope * ca.fmin(x.m, 0), x.shape_)


def clamp(x, min=None, max=None):  # noqa: A002 (torch's names)
    x = lift(x)
    m = x.m
    if min is not None:
        m = ca.fmax(m, lift(min).m) if not isinstance(min, SymTensor) else binary(ca.fmax, x, min).m
    if max is not None:
        m = ca.fmin(m, lift(max).m) if not isinstance(max, SymTensor) else binary(ca.fmin, x, max).m
    return SymTensor(m, x.shape_)


def identity(x, *args, **kwargs):
    return x


def to(x, *args, **kwargs):
    """``.to(dtype)``/``.to(device)``: the symbolic value is float64 or a mask; only ``bool`` changes it."""
    dtype = kwargs.get("dtype")
    for arg in args:
        if isinstance(arg, torch.dtype):
            dtype = arg
        elif isinstance(arg, (torch.Tensor, SymTensor)):
            dtype = arg.dtype
    x = lift(x)
    if dtype == torch.bool:
        return x if x.is_bool else SymTensor(x.m != 0, x.shape_, True)
    if dtype is not None and not dtype.is_floating_point:
        raise ExportError(f"conversion to {dtype} (only float and bool tensors export)", current_module())
    return as_float(x)


def logical_not(x):
    x = lift(x)
    return SymTensor(1 - (x.m != 0), x.shape_, True)


# ------------------------------------------------------------------------------------------- data movement
def reshape(x, *shape):
    x = lift(x)
    target = list(_shape_args(shape))
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
    start, end = _dims(start_dim, x.ndim), _dims(end_dim, x.ndim)
    shape = x.shape_[:start] + (math.prod(x.shape_[start : end + 1]),) + x.shape_[end + 1 :]
    return reshape(x, shape)


def unsqueeze(x, dim):
    x = lift(x)
    dim = _dims(dim, x.ndim + 1)
    return reshape(x, x.shape_[:dim] + (1,) + x.shape_[dim:])


def squeeze(x, dim=None):
    x = lift(x)
    if dim is None:
        dims = {i for i, s in enumerate(x.shape_) if s == 1}
    else:
        dims = {_dims(d, x.ndim) for d in (dim if isinstance(dim, (tuple, list)) else (dim,))}
        dims = {d for d in dims if x.shape_[d] == 1}
    return reshape(x, tuple(s for i, s in enumerate(x.shape_) if i not in dims))


def permute(x, *dims):
    x = lift(x)
    order = tuple(_dims(d, x.ndim) for d in _shape_args(dims))
    return gather_like(x, np.transpose(arange_of(x), order))


def transpose(x, dim0, dim1):
    x = lift(x)
    order = list(range(x.ndim))
    a, b = _dims(dim0, x.ndim), _dims(dim1, x.ndim)
    order[a], order[b] = order[b], order[a]
    return permute(x, tuple(order))


def expand(x, *sizes):
    x = lift(x)
    target = _shape_args(sizes)
    padded = (1,) * (len(target) - x.ndim) + x.shape_
    shape = tuple(p if t == -1 else t for p, t in zip(padded, target, strict=True))
    return broadcast_to(reshape(x, padded), shape)


def expand_as(x, other):
    return expand(x, tuple(other.shape))


def repeat(x, *sizes):
    x = lift(x)
    return gather_like(x, np.tile(arange_of(x), _shape_args(sizes)))


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
    key = (slice(None),) * _dims(dim, x.ndim) + (index,)
    return getitem(x, key)


def narrow(x, dim, start, length):
    x = lift(x)
    key = (slice(None),) * _dims(dim, x.ndim) + (slice(start, start + length),)
    return getitem(x, key)


def cat(tensors: Sequence[Any], dim=0, *, out=None):
    parts = [lift(t) for t in tensors if not (isinstance(t, torch.Tensor) and t.numel() == 0 and t.ndim == 1)]
    ndim = parts[0].ndim
    dim = _dims(dim, ndim)
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
    dim = _dims(dim, parts[0].ndim + 1)
    return cat([unsqueeze(p, dim) for p in parts], dim)


def chunk(x, chunks, dim=0):
    x = lift(x)
    size = math.ceil(x.shape_[_dims(dim, x.ndim)] / chunks)
    return split(x, size, dim)


def split(x, size, dim=0):
    x = lift(x)
    dim = _dims(dim, x.ndim)
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
    return tuple(select(x, dim, i) for i in range(x.shape_[_dims(dim, x.ndim)]))


# ------------------------------------------------------------------------------------------- reductions
def _to_last(x: SymTensor, dims: Sequence[int]) -> tuple[SymTensor, tuple[int, ...]]:
    """``x`` with ``dims`` moved to the end and merged into one column block; the kept shape."""
    keep = [d for d in range(x.ndim) if d not in dims]
    moved = (
        permute(x, tuple(keep + list(dims))) if list(dims) != list(range(x.ndim - len(dims), x.ndim)) else x
    )
    kept = tuple(x.shape_[d] for d in keep)
    return reshape(moved, kept + (math.prod(x.shape_[d] for d in dims),)), kept


def _reduce_dims(x: SymTensor, dim) -> list[int]:
    if dim is None:
        return list(range(x.ndim))
    dims = dim if isinstance(dim, (tuple, list)) else (dim,)
    return sorted(_dims(d, x.ndim) for d in dims)


def reduce_sum(x, dim=None, keepdim=False, *, dtype=None):
    x = as_float(lift(x))
    if not x.shape_:
        return x
    dims = _reduce_dims(x, dim)
    merged, kept = _to_last(x, dims)
    out = SymTensor(ca.sum2(merged.m), kept + (1,))
    shape = tuple(1 if d in dims else s for d, s in enumerate(x.shape_)) if keepdim else kept
    return reshape(out, shape)


def mean(x, dim=None, keepdim=False, *, dtype=None):
    x = lift(x)
    count = math.prod(x.shape_[d] for d in _reduce_dims(x, dim))
    total = reduce_sum(x, dim, keepdim)
    return SymTensor(total.m / count, total.shape_)


def _row_max(m):
    top = m[:, 0]
    for j in range(1, m.shape[1]):
        top = ca.fmax(top, m[:, j])
    return top


def _softmax_rows(m, mask=None):
    """Softmax of every row of ``m``; ``mask`` (0/1, same shape) leaves entries out exactly as -inf would."""
    cols = m.shape[1]
    shifted = m if mask is None else ca.if_else(mask, m, -1e300, False)
    # The shift by the row's maximum changes no value (softmax is shift invariant) but keeps exp finite.
    e = ca.exp(m - ca.repmat(_row_max(shifted), 1, cols))
    if mask is not None:
        e = ca.if_else(mask, e, 0, False)
    return e / ca.repmat(ca.sum2(e), 1, cols)


def softmax(x, dim=None, _stacklevel=3, dtype=None):
    x = as_float(lift(x))
    dim = _dims(x.ndim - 1 if dim is None else dim, x.ndim)
    if dim == x.ndim - 1:
        return SymTensor(_softmax_rows(x.m), x.shape_)
    order = [d for d in range(x.ndim) if d != dim] + [dim]
    inverse = np.argsort(order).tolist()
    moved = permute(x, tuple(order))
    return permute(SymTensor(_softmax_rows(moved.m), moved.shape_), tuple(inverse))


def log_softmax(x, dim=None, _stacklevel=3, dtype=None):
    y = softmax(x, dim)
    return SymTensor(ca.log(y.m), y.shape_)


# ------------------------------------------------------------------------------------------- linear algebra
def linear(x, weight, bias=None):
    x = lift(x)
    w = constant(weight) if not isinstance(weight, SymTensor) else None
    if w is None:
        return (
            add(matmul(x, transpose(weight, 0, 1)), bias)
            if bias is not None
            else matmul(x, transpose(weight, 0, 1))
        )
    out = ca.mtimes(x.m, ca.DM(w.T))
    if bias is not None:
        out = out + ca.repmat(ca.DM(constant(bias).reshape(1, -1)), out.shape[0], 1)
    return SymTensor(out, x.shape_[:-1] + (w.shape[0],))


def matmul(a, b):
    x, y = lift(a), lift(b)
    if x.ndim == 1:
        return squeeze(matmul(unsqueeze(x, 0), y), -2)
    if y.ndim == 1:
        return squeeze(matmul(x, unsqueeze(y, -1)), -1)
    n, k = x.shape_[-2:]
    p = y.shape_[-1]
    if y.shape_[-2] != k:
        raise ExportError(f"matmul of {x.shape_} and {y.shape_}", current_module())
    if y.ndim == 2:  # one mtimes over all leading dims of x
        return SymTensor(ca.mtimes(x.m, y.m), x.shape_[:-1] + (p,))
    batch = tuple(np.broadcast_shapes(x.shape_[:-2], y.shape_[:-2]))
    x = broadcast_to(x, batch + (n, k))
    y = broadcast_to(y, batch + (k, p))
    blocks = [
        ca.mtimes(x.m[i * n : (i + 1) * n, :], y.m[i * k : (i + 1) * k, :]) for i in range(math.prod(batch))
    ]
    return SymTensor(ca.vertcat(*blocks), batch + (n, p))


def einsum(equation: str, *operands):
    """Two-operand (or one-operand) einsum as permutes, sums and one batched matmul."""
    if len(operands) == 1 and isinstance(operands[0], (list, tuple)):
        operands = tuple(operands[0])
    equation = equation.replace(" ", "")
    if "..." in equation or "->" not in equation or len(operands) not in (1, 2):
        raise ExportError(
            f"einsum {equation!r} (explicit '->', one or two operands, no '...')", current_module()
        )
    inputs, output = equation.split("->")
    specs = inputs.split(",")
    tensors = [lift(t) for t in operands]
    if len(tensors) == 1:
        (spec,), (x,) = specs, tensors
        summed = [i for i, c in enumerate(spec) if c not in output]
        kept = "".join(c for c in spec if c in output)
        y = reduce_sum(x, summed) if summed else x
        return permute(y, tuple(kept.index(c) for c in output)) if kept != output else y
    (sa, sb), (a, b) = specs, tensors
    # letters seen by one operand only and not in the output are summed out first
    for which in (0, 1):
        spec, other = (sa, sb) if which == 0 else (sb, sa)
        lonely = [i for i, c in enumerate(spec) if c not in other and c not in output]
        if lonely:
            reduced = reduce_sum(a if which == 0 else b, lonely)
            spec = "".join(c for i, c in enumerate(spec) if i not in lonely)
            if which == 0:
                a, sa = reduced, spec
            else:
                b, sb = reduced, spec
    batch = [c for c in sa if c in sb and c in output]
    contract = [c for c in sa if c in sb and c not in output]
    left = [c for c in sa if c not in sb]
    right = [c for c in sb if c not in sa]
    size = {c: a.shape_[sa.index(c)] for c in sa} | {c: b.shape_[sb.index(c)] for c in sb}

    def arrange(x: SymTensor, spec: str, groups: list[list[str]]) -> SymTensor:
        order = [spec.index(c) for g in groups for c in g]
        y = permute(x, tuple(order)) if order != list(range(len(spec))) else x
        return reshape(y, tuple(math.prod(size[c] for c in g) for g in groups))

    lhs = arrange(a, sa, [batch, left, contract])
    rhs = arrange(b, sb, [batch, contract, right])
    product = matmul(lhs, rhs)  # (batch, left, right)
    order_now = batch + left + right
    result = reshape(product, tuple(size[c] for c in order_now))
    perm = tuple(order_now.index(c) for c in output)
    return permute(result, perm) if perm != tuple(range(len(perm))) else result


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
            mask = _operand(m, scores.shape_)
        else:
            scores = add(scores, m)
    weights = SymTensor(_softmax_rows(scores.m, mask), scores.shape_)
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
        return maker(_shape_args(size), dtype=dtype)

    return make


def new_full(x, size, fill_value, *, dtype=None, **kwargs):
    return torch.full(_shape_args((size,)), fill_value, dtype=torch.float64)


# ------------------------------------------------------------------------------------------------- tables
def _comparison(op):
    return lambda a, b: binary(op, a, b, is_bool=True)


def _logical(op):
    return lambda a, b: binary(lambda p, q: op(p != 0, q != 0), a, b, is_bool=True)


ELEMENTWISE: dict[str, Callable[[Any], Any]] = {
    "tanh": ca.tanh,
    "sigmoid": sigmoid,
    "relu": lambda m: ca.fmax(m, 0),
    "exp": ca.exp,
    "log": ca.log,
    "log1p": ca.log1p,
    "sqrt": ca.sqrt,
    "rsqrt": lambda m: 1 / ca.sqrt(m),
    "abs": ca.fabs,
    "neg": lambda m: -m,
    "square": lambda m: m**2,
    "sin": ca.sin,
    "cos": ca.cos,
    "erf": ca.erf,
    "silu": lambda m: m * sigmoid(m),
}

BINARY: dict[str, Callable[..., Any]] = {
    "add": add,
    "sub": sub,
    "mul": mul,
    "div": div,
    "true_divide": div,
    "pow": power,
    "maximum": lambda a, b: binary(ca.fmax, a, b),
    "minimum": lambda a, b: binary(ca.fmin, a, b),
    "eq": _comparison(lambda p, q: p == q),
    "ne": _comparison(lambda p, q: p != q),
    "ge": _comparison(lambda p, q: p >= q),
    "gt": _comparison(lambda p, q: p > q),
    "le": _comparison(lambda p, q: p <= q),
    "lt": _comparison(lambda p, q: p < q),
    "logical_and": _logical(ca.logic_and),
    "logical_or": _logical(ca.logic_or),
}

SHAPING: dict[str, Callable[..., Any]] = {
    "reshape": reshape,
    "view": reshape,
    "flatten": flatten,
    "unsqueeze": unsqueeze,
    "squeeze": squeeze,
    "permute": permute,
    "transpose": transpose,
    "swapaxes": transpose,
    "expand": expand,
    "expand_as": expand_as,
    "repeat": repeat,
    "select": select,
    "narrow": narrow,
    "chunk": chunk,
    "split": split,
    "unbind": unbind,
    "sum": reduce_sum,
    "mean": mean,
    "softmax": softmax,
    "log_softmax": log_softmax,
    "matmul": matmul,
    "mm": matmul,
    "bmm": matmul,
    "clamp": clamp,
    "clip": clamp,
    "where": lambda x, condition, other: where(condition, x, other),
    "logical_not": logical_not,
}


def _register() -> None:
    for name, op in ELEMENTWISE.items():
        handler = unary(op)
        METHODS[name] = handler
        for owner in (torch, torch.Tensor):
            if hasattr(owner, name):
                HANDLERS[getattr(owner, name)] = handler
        if hasattr(F, name):
            HANDLERS[getattr(F, name)] = handler
    for name, op in BINARY.items():
        METHODS[name] = op
        for owner in (torch, torch.Tensor):
            if hasattr(owner, name):
                HANDLERS[getattr(owner, name)] = op
    for name, op in SHAPING.items():
        METHODS[name] = op
        for owner in (torch, torch.Tensor):
            if hasattr(owner, name):
                HANDLERS[getattr(owner, name)] = op
    dunder: dict[str, Callable[..., Any]] = {
        "__add__": add,
        "__radd__": lambda a, b: add(b, a),
        "__sub__": sub,
        "__rsub__": lambda a, b: sub(b, a),
        "__mul__": mul,
        "__rmul__": lambda a, b: mul(b, a),
        "__truediv__": div,
        "__rtruediv__": lambda a, b: div(b, a),
        "__div__": div,
        "__rdiv__": lambda a, b: div(b, a),
        "__pow__": power,
        "__rpow__": lambda a, b: power(b, a),
        "__matmul__": matmul,
        "__rmatmul__": lambda a, b: matmul(b, a),
        "__and__": BINARY["logical_and"],
        "__rand__": BINARY["logical_and"],
        "__or__": BINARY["logical_or"],
        "__ror__": BINARY["logical_or"],
        "__invert__": logical_not,
        "__neg__": unary(ELEMENTWISE["neg"]),
        "__getitem__": getitem,
        "__eq__": BINARY["eq"],
        "__ne__": BINARY["ne"],
        "__ge__": BINARY["ge"],
        "__gt__": BINARY["gt"],
        "__le__": BINARY["le"],
        "__lt__": BINARY["lt"],
    }
    for name, op in dunder.items():
        setattr(SymTensor, name, op)
        HANDLERS[getattr(torch.Tensor, name)] = op
    HANDLERS.update(
        {
            torch.cat: cat,
            torch.concat: cat,
            torch.concatenate: cat,
            torch.stack: stack,
            torch.where: where,
            torch.einsum: einsum,
            torch.zeros_like: zeros_like,
            torch.ones_like: ones_like,
            torch.full_like: full_like,
            torch.Tensor.to: to,
            torch.Tensor.type_as: lambda x, other: to(x, other.dtype),
            F.linear: linear,
            F.relu: HANDLERS[torch.relu],
            F.gelu: gelu,
            F.softplus: softplus,
            F.leaky_relu: leaky_relu,
            F.softmax: softmax,
            F.log_softmax: log_softmax,
            F.layer_norm: layer_norm,
            F.scaled_dot_product_attention: scaled_dot_product_attention,
            F.dropout: dropout,
            torch.Tensor.detach: identity,
            torch.Tensor.contiguous: identity,
            torch.Tensor.clone: identity,
        }
    )
    METHODS.update(
        {
            "to": to,
            "float": lambda x: as_float(x),
            "double": lambda x: as_float(x),
            "bool": lambda x: to(x, torch.bool),
            "type_as": lambda x, other: to(x, other.dtype),
            "detach": identity,
            "contiguous": identity,
            "clone": identity,
            "new_zeros": new_constant(torch.zeros),
            "new_ones": new_constant(torch.ones),
            "new_full": new_full,
            "add": add,
            "relu": HANDLERS[torch.relu],
        }
    )


_register()
