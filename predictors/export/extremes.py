"""The largest and smallest entries: ``amax``/``amin``, and ``torch.max``/``torch.min`` (``x.max(dim)``).

Both give torch's values and torch's gradient at a tie: ``amax`` (and ``torch.max(x)`` without a dim) shares
it evenly among the equal entries, ``torch.max(x, dim)`` gives it all to the first of them, the one whose
index torch returns. Those indices cannot be exported (a function of the inputs' values gives numbers with a
derivative, not positions): the values come back with an ``Unexportable`` in their place, refused where a
later operation uses it.

A NaN is the extreme, as in torch, where CasADi's fmax (``row_max``) passes over it: the NaN entries join the
ties (``amax``), or alone are the ties (``torch.max(x, dim)``: the first NaN, whose index torch returns and to
which its gradient goes). Rows without a NaN keep their values and Jacobians.
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from typing import Any

import casadi as ca
import torch

from predictors.export.elementwise import binary, is_nan
from predictors.export.errors import ExportError, current_module
from predictors.export.linalg import reduce_dims, row_max, to_last
from predictors.export.movement import normal_dim, reshape
from predictors.export.symbolic import SymTensor, Unexportable, as_float, lift


def _kept_shape(x: SymTensor, dims: list[int], keepdim: bool, kept: tuple[int, ...]) -> tuple[int, ...]:
    return tuple(1 if d in dims else s for d, s in enumerate(x.shape_)) if keepdim else kept


def _extreme(x, dim, keepdim, sign: int) -> SymTensor:
    """The largest (``sign`` 1) or smallest (-1) entry over ``dim``, as torch's amax / amin: the mean of the
    entries that equal it, so that ties share the gradient evenly, as torch's does (a chain of fmax gave
    three equal entries 1/4, 1/4 and 1/2). The comparisons' derivative is 0."""
    x = as_float(lift(x))
    if not x.shape_:
        return x
    dims = reduce_dims(x, dim)
    merged, kept = to_last(x, dims)
    m = merged.m * sign
    top = ca.repmat(row_max(m), 1, m.shape[1])
    ties = ca.logic_or(m == top, is_nan(m))  # a NaN among them makes the mean NaN, torch's value
    # if_else, not m * ties: an entry of -inf that is not the extreme would make 0 * -inf NaN
    value = ca.sum2(ca.if_else(ties, merged.m, 0)) / ca.sum2(ties)
    return reshape(SymTensor(value, kept + (1,)), _kept_shape(x, dims, keepdim, kept))


def amax(x, dim=(), keepdim=False, *, out=None):
    return _extreme(x, dim, keepdim, 1)


def amin(x, dim=(), keepdim=False, *, out=None):
    return _extreme(x, dim, keepdim, -1)


def _nan_first(extreme: Callable[[Any, Any], Any]) -> Callable[[Any, Any], Any]:
    """``extreme`` (ca.fmax, ca.fmin: torch's slope 0.5 at a tie) of two entries, NaN where either is NaN,
    as torch.maximum and torch.minimum, where fmax gives the other entry."""

    def apply(p, q):
        return ca.if_else(ca.logic_or(is_nan(p), is_nan(q)), p + q, extreme(p, q), False)

    return apply


def maximum(a, b):
    return binary(_nan_first(ca.fmax), a, b)


def minimum(a, b):
    return binary(_nan_first(ca.fmin), a, b)


def _first_extreme(x: SymTensor, dim: int, keepdim: bool, sign: int) -> SymTensor:
    """The values of ``torch.max(x, dim)`` (``sign`` 1) or ``torch.min`` (-1): the first entry over ``dim``
    that equals the extreme, whose index torch returns and to which its gradient goes (a bool tensor's stay
    a mask, as torch's)."""
    is_bool = x.is_bool
    x = as_float(x)
    if not x.shape_:
        normal_dim(dim, 0)  # torch takes dim 0 or -1 of a 0-d tensor
        return SymTensor(x.m, (), is_bool)
    dims = [normal_dim(dim, x.ndim)]
    merged, kept = to_last(x, dims)
    m = merged.m * sign
    top = ca.repmat(row_max(m), 1, m.shape[1])
    # in a row that holds a NaN, torch's extreme is its first NaN: the NaN entries are then the ties
    nan = is_nan(m)
    has_nan = ca.repmat(ca.sum2(nan) > 0, 1, m.shape[1])
    ties = ca.if_else(has_nan, nan, m == top, False)
    value: Any = 0
    taken: Any = 0  # whether an earlier entry of the row was the extreme
    for j in range(m.shape[1]):
        tie = ties[:, j]
        first = ca.logic_and(tie, ca.logic_not(taken)) if j else tie
        # if_else, as in _extreme: an entry of -inf that is not taken must not make 0 * -inf NaN
        value = value + ca.if_else(first, merged.m[:, j], 0)
        taken = ca.logic_or(taken, tie) if j else tie
    out = SymTensor(value, kept + (1,), is_bool)
    return reshape(out, _kept_shape(x, dims, keepdim, kept))


def values_and_indices(call: str, sign: int, result: Callable[[Any], Any]) -> Callable[..., Any]:
    """The handler of ``call`` (``torch.max(x, dim)``, ``x.max(dim)``; ``sign`` -1 for the min): torch's
    three forms, the extreme of every entry, the elementwise extreme of two tensors, and over ``dim`` the pair
    (values, indices) as ``result`` (``torch.return_types.max``) holds them, the indices ``Unexportable``."""
    name = call.split("(")[0]
    every, pairwise, kind = (amax, maximum, "amax") if sign > 0 else (amin, minimum, "amin")
    why = (
        f"the indices of {call} are used: indices cannot be exported, only values: use {call}.values or "
        f"torch.{kind}(x, dim)"
    )

    def handler(x, dim_or_other=None, keepdim=False, *, dim=None, other=None, out=None):
        if out is not None:
            raise ExportError(f"{name} with out= (a write into a tensor)", current_module())
        # torch takes a tensor in the second place for the other operand, but one named dim= for the dim
        # (an integer 0-d tensor): taken as the other, torch.max(x, dim=torch.tensor(0)) ran as a maximum
        if isinstance(dim_or_other, (SymTensor, torch.Tensor)):
            other = dim_or_other
        elif dim_or_other is not None:
            dim = dim_or_other
        if other is not None:
            return pairwise(x, other)
        x = lift(x)
        if dim is None:
            return SymTensor(every(x).m, (), x.is_bool)
        try:
            dim = operator.index(dim)
        except TypeError:
            raise ExportError(
                f"{name} over dim={dim!r} (one int, as torch takes; torch.{kind} takes several)",
                current_module(),
            ) from None
        return result((_first_extreme(x, dim, keepdim, sign), Unexportable(why)))

    return handler
