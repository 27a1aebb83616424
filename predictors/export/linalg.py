"""Reductions (the extremes are ``predictors.export.extremes``), softmax, linear layers, matmul and einsum."""

from __future__ import annotations

import math
from collections.abc import Sequence

import casadi as ca
import numpy as np

from predictors.export.elementwise import add, clamp, div, mul, sub
from predictors.export.errors import ExportError, current_module
from predictors.export.movement import normal_dim, permute, reshape, squeeze, transpose, unsqueeze
from predictors.export.symbolic import (
    SymTensor,
    as_float,
    broadcast_to,
    constant,
    lift,
)


# ------------------------------------------------------------------------------------------- reductions
def to_last(x: SymTensor, dims: Sequence[int]) -> tuple[SymTensor, tuple[int, ...]]:
    """``x`` with ``dims`` moved to the end and merged into one column block; the kept shape."""
    keep = [d for d in range(x.ndim) if d not in dims]
    moved = (
        permute(x, tuple(keep + list(dims))) if list(dims) != list(range(x.ndim - len(dims), x.ndim)) else x
    )
    kept = tuple(x.shape_[d] for d in keep)
    return reshape(moved, kept + (math.prod(x.shape_[d] for d in dims),)), kept


def reduce_dims(x: SymTensor, dim) -> list[int]:
    if dim is None or (isinstance(dim, (tuple, list)) and not dim):  # torch reduces every dim for dim=[]
        return list(range(x.ndim))
    dims = dim if isinstance(dim, (tuple, list)) else (dim,)
    return sorted(normal_dim(d, x.ndim) for d in dims)


def reduce_sum(x, dim=None, keepdim=False, *, dtype=None):
    x = as_float(lift(x))
    if not x.shape_:
        return x
    dims = reduce_dims(x, dim)
    merged, kept = to_last(x, dims)
    out = SymTensor(ca.sum2(merged.m), kept + (1,))
    shape = tuple(1 if d in dims else s for d, s in enumerate(x.shape_)) if keepdim else kept
    return reshape(out, shape)


def mean(x, dim=None, keepdim=False, *, dtype=None):
    x = lift(x)
    count = math.prod(x.shape_[d] for d in reduce_dims(x, dim))
    total = reduce_sum(x, dim, keepdim)
    return SymTensor(total.m / count, total.shape_)


def _count_true(x, dim, keepdim) -> tuple[SymTensor, int]:
    """How many entries over ``dim`` are true (nonzero, as torch reads a number), and of how many."""
    x = lift(x)
    nonzero = SymTensor(x.m != 0, x.shape_)  # 0/1, summed exactly
    return reduce_sum(nonzero, dim, keepdim), math.prod(x.shape_[d] for d in reduce_dims(x, dim))


def any_true(x, dim=None, keepdim=False, *, out=None):
    """``torch.any`` and ``x.any(dim)``: a mask."""
    count, _ = _count_true(x, dim, keepdim)
    return SymTensor(count.m > 0, count.shape_, True)


def all_true(x, dim=None, keepdim=False, *, out=None):
    """``torch.all`` and ``x.all(dim)``: a mask."""
    count, total = _count_true(x, dim, keepdim)
    return SymTensor(count.m == total, count.shape_, True)


# The 2-norm's names in torch, each with the orders that are the 2-norm of the reduced entries (a matrix's
# Frobenius norm too); other orders (1, inf, 'nuc', a matrix's spectral ord=2) are refused.
TWO_NORM_ORDERS = (2, 2.0, "fro", None)


def two_norm(x, dim=None, keepdim=False):
    """sqrt of the sum of squares over ``dim``, with torch's gradient at 0: 0 (its subgradient), where
    sqrt's would be inf and a pair's distance to itself (always 0) made every Jacobian NaN; NaN where the sum
    is, as torch's."""
    squares = reduce_sum(mul(x, x), dim, keepdim)
    m = squares.m
    positive = m != 0  # as m > 0 for a sum of squares, and true for NaN, which m > 0 sent to 0
    # sqrt is taken of 1 where the sum is 0, so neither branch's derivative is inf there
    return SymTensor(ca.if_else(positive, ca.sqrt(ca.if_else(positive, m, 1)), 0), squares.shape_)


def _order(name: str, order, allowed=TWO_NORM_ORDERS) -> None:
    if order not in allowed:
        raise ExportError(f"{name} of order {order!r} (the export maps the 2-norm only)", current_module())


def norm(x, p="fro", dim=None, keepdim=False, out=None, dtype=None):
    """``torch.norm`` and ``Tensor.norm``."""
    _order("torch.norm", p)
    return two_norm(lift(x), dim, keepdim)


def vector_norm(x, ord=2, dim=None, keepdim=False, *, dtype=None, out=None):  # noqa: A002 (torch's name)
    _order("torch.linalg.vector_norm", ord, (2, 2.0))
    return two_norm(lift(x), dim, keepdim)


def linalg_norm(x, ord=None, dim=None, keepdim=False, *, out=None, dtype=None):  # noqa: A002
    """``torch.linalg.norm``: the vector 2-norm, or a matrix's Frobenius norm (``ord`` None or 'fro')."""
    x = lift(x)
    matrix = len(reduce_dims(x, dim)) == 2 if dim is not None else x.ndim == 2
    _order("torch.linalg.norm", ord, (None, "fro") if matrix else (None, 2, 2.0))
    return two_norm(x, dim, keepdim)


def normalize(x, p=2.0, dim=1, eps=1e-12, out=None):
    """``F.normalize``: ``x / max(||x||, eps)`` along ``dim``."""
    _order("torch.nn.functional.normalize", p, (2, 2.0))
    x = lift(x)
    return div(x, clamp(two_norm(x, dim, keepdim=True), min=eps))


# torch.cdist's compute modes: each gives the same distances up to rounding (with more than 25 rows torch's
# default takes them from a matmul, 1.5e-8 off at 0 in float64), and the export computes them directly
CDIST_MODES = (
    None,
    "use_mm_for_euclid_dist_if_necessary",
    "use_mm_for_euclid_dist",
    "donot_use_mm_for_euclid_dist",
)


def cdist(x1, x2, p=2.0, compute_mode=None):
    """``torch.cdist`` for p = 2: ``(..., P, M)`` and ``(..., R, M)``, batch dims broadcast, to the distances
    ``(..., P, R)``, through ``two_norm``: an agent's distance to itself (0) has torch's gradient there, 0."""
    _order("torch.cdist", p, (2, 2.0))
    if compute_mode not in CDIST_MODES:
        raise ExportError(
            f"torch.cdist compute_mode {compute_mode!r} (one of {CDIST_MODES})", current_module()
        )
    a, b = as_float(lift(x1)), as_float(lift(x2))
    if a.ndim < 2 or b.ndim < 2 or a.shape_[-1] != b.shape_[-1]:
        raise ExportError(
            f"torch.cdist of shapes {a.shape_} and {b.shape_} (expected (..., P, M) and (..., R, M))",
            current_module(),
        )
    # (..., P, 1, M) - (..., 1, R, M): every pair's difference, the batch dims broadcast as torch does
    return two_norm(sub(unsqueeze(a, -2), unsqueeze(b, -3)), -1)


def row_max(m):
    top = m[:, 0]
    for j in range(1, m.shape[1]):
        top = ca.fmax(top, m[:, j])
    return top


def softmax_rows(m, mask=None, *, empty_rows_zero=False):
    """Softmax of every row of ``m``; ``mask`` (0/1, same shape) leaves entries out exactly as -inf would.

    A row that ``mask`` leaves empty is 0/0 (NaN, as torch's softmax of all -inf) unless ``empty_rows_zero``
    (torch's attention, whose softmax gives such a row 0: an agent with no neighbour in range).
    """
    cols = m.shape[1]
    if cols == 0:  # rows of no entry (attention over no key: a crowd of none), as torch's: row_max needs one
        return m
    shifted = m if mask is None else ca.if_else(mask, m, -1e300, False)
    # The shift by the row's maximum changes no value (softmax is shift invariant) but keeps exp finite.
    e = ca.exp(m - ca.repmat(row_max(shifted), 1, cols))
    if mask is not None:
        e = ca.if_else(mask, e, 0, False)
    total = ca.sum2(e)
    if empty_rows_zero:
        # a row with an allowed key sums to >= 1 (exp(0) at its maximum): only empty rows are 0
        total = ca.if_else(total > 0, total, 1, False)
    return e / ca.repmat(total, 1, cols)


def log_softmax_rows(m):
    """``log(softmax)`` of every row as ``m - max - log(sum(exp(m - max)))``: the log of a softmax that has
    underflowed would be -inf (a logit gap above ~745) where torch's is exact."""
    cols = m.shape[1]
    if cols == 0:  # as softmax_rows
        return m
    shifted = m - ca.repmat(row_max(m), 1, cols)
    return shifted - ca.repmat(ca.log(ca.sum2(ca.exp(shifted))), 1, cols)


def _along(rows_fn, x, dim) -> SymTensor:
    """``rows_fn`` (a map of every row of a matrix) applied along ``dim`` of ``x``."""
    x = as_float(lift(x))
    dim = normal_dim(dim, x.ndim)
    if dim == x.ndim - 1:
        return SymTensor(rows_fn(x.m), x.shape_)
    order = [d for d in range(x.ndim) if d != dim] + [dim]
    inverse = np.argsort(order).tolist()
    moved = permute(x, tuple(order))
    return permute(SymTensor(rows_fn(moved.m), moved.shape_), tuple(inverse))


def _given(dim, name: str) -> int:
    if dim is None:  # torch's implicit dim (dim 0 of a 0-, 1- or 3-D input), deprecated, is not the last one
        raise ExportError(
            f"{name} without dim (torch's deprecated implicit choice, dim 0 of a 1- or 3-D input): pass dim",
            current_module(),
        )
    return dim


def softmax(x, dim=None, _stacklevel=3, dtype=None):
    return _along(softmax_rows, x, _given(dim, "softmax"))


def log_softmax(x, dim=None, _stacklevel=3, dtype=None):
    return _along(log_softmax_rows, x, _given(dim, "log_softmax"))


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
    if x.ndim == 1 and y.ndim == 1:  # a dot product, 0-d as in torch
        return reshape(matmul(unsqueeze(x, 0), unsqueeze(y, -1)), ())
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
    # no blocks for a batch of none: vertcat of nothing is 0-by-1, not the 0-by-p of the empty result
    return SymTensor(ca.vertcat(*blocks) if blocks else type(x.m)(0, p), batch + (n, p))


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
    if any(len(set(spec)) != len(spec) for spec in specs):
        raise ExportError(
            f"einsum {equation!r} (a letter repeated within one operand: a diagonal or trace)",
            current_module(),
        )
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
