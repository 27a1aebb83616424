"""Elementwise arithmetic, activations, comparisons and masks, as whole-matrix CasADi operations."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np
import torch

from predictors.export.errors import ExportError, current_module
from predictors.export.symbolic import (
    SymTensor,
    as_float,
    broadcast_to,
    constant,
    lift,
    rows_cols,
)


# ----------------------------------------------------------------------------------------------- elementwise
def operand(x: SymTensor, shape: tuple[int, ...]) -> Any:
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
    return SymTensor(op(operand(x, shape), operand(y, shape)), shape, is_bool)


def _is_mask(value: Any) -> bool:
    """Whether torch holds ``value`` as bool: a mask, a bool tensor or a Python bool."""
    if isinstance(value, SymTensor):
        return value.is_bool
    if isinstance(value, torch.Tensor):
        return value.dtype == torch.bool
    return isinstance(value, (bool, np.bool_))


def _mask_op(op: Callable[[Any, Any], Any], a: Any, b: Any) -> SymTensor:
    return binary(lambda p, q: op(p != 0, q != 0), a, b, is_bool=True)


def add(a, b, *, alpha=1):
    if _is_mask(a) and _is_mask(b):  # torch's sum of two masks is a mask, their or: never 2
        if alpha != 1:
            raise ExportError(f"sum of two bool tensors with alpha={alpha!r}", current_module())
        return _mask_op(ca.logic_or, a, b)
    if alpha != 1:
        b = mul(b, alpha)
    for sym, other in ((a, b), (b, a)):  # x + 0: no node (masks of ones and zeros are common)
        if isinstance(sym, SymTensor) and _is_constant(other, 0.0):
            if tuple(np.broadcast_shapes(sym.shape_, tuple(np.shape(constant(other))))) == sym.shape_:
                return as_float(sym)
    return binary(lambda p, q: p + q, a, b)


def sub(a, b, *, alpha=1):
    if _is_mask(a) or _is_mask(b):  # torch raises here: a numeric difference would export code torch refuses
        raise ExportError(
            "subtraction with a bool tensor (torch refuses it: invert a mask with ~, compare two with ^)",
            current_module(),
        )
    return add(a, mul(b, -alpha) if isinstance(b, SymTensor) else -alpha * constant(b))


def mul(a, b):
    if _is_mask(a) and _is_mask(b):  # torch's product of two masks is a mask, their and
        return _mask_op(ca.logic_and, a, b)
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
        ca.if_else(operand(c, shape), operand(x, shape), operand(y, shape), False), shape, x.is_bool
    )


def is_nan(m):
    """1 where ``m`` is NaN, else 0: NaN fails every comparison, and this is one CasADi keeps (it folds
    ``m != m`` to 0, as if no entry could be NaN)."""
    return ca.logic_not(m <= math.inf)


def unary(op: Callable[[Any], Any]) -> Callable[..., SymTensor]:
    def apply(x, *args, **kwargs):
        x = lift(x)
        return SymTensor(op(x.m), x.shape_)

    return apply


# torch's 1 / (1 + exp(-x)) overflows exp(-x) to inf below x = -709.78: the value is still right (0), its
# derivative 0 * inf is NaN (torch's is 0). With x held at -709 below that, the sigmoid there is 1.2e-308
# (torch: 0 to 1.2e-308) and its derivative 0 (torch: at most 1.2e-308). The bound goes on the argument, not
# an if_else on the result: CasADi still rewrites t * (1 / u) as t / u, so the twins keep their values to the
# bit.
_SIGMOID_FLOOR = -709.0

# NaN fails every comparison, so each if_else below tests the condition under which the result is not the
# input (m <= 0 for relu): a NaN input then takes the input's branch and stays NaN, as in torch (relu, clamp
# and sigmoid of NaN are NaN), where m > 0 sent it to the constant. Finite inputs take the same branch as
# with the converse test, so their values and derivatives are unchanged.


def sigmoid(m):
    return 1 / (1 + ca.exp(-ca.if_else(m <= _SIGMOID_FLOOR, _SIGMOID_FLOOR, m, False)))


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


# CasADi differentiates fmax/fmin with slope 0.5 at a tie; torch gives relu slope 0 at 0, leaky_relu its
# negative slope and clamp 1 at a bound. Ties are not rare: soft pooling's relu(1 - |u - c|) is exactly 0
# whenever two agents sit a whole number of half cells apart (the scenarios' formations do). Hence if_else,
# which has torch's derivative and the same values.
def relu(m):
    # one node more than fmax (the comparison), yet no slower: every shipped net's encoder and twin took
    # 0.96-1.00x the time of the fmax form, alternating calls of both in one process; and one more for NaN
    # (the not of m <= 0, see above)
    return ca.if_else(m <= 0, 0, m, False)


def leaky_relu(x, negative_slope=0.01, inplace=False):
    x = lift(x)
    return SymTensor(ca.if_else(x.m > 0, x.m, negative_slope * x.m, False), x.shape_)


def _at_least(p, q):
    return ca.if_else(p < q, q, p, False)


def _at_most(p, q):
    return ca.if_else(p > q, q, p, False)


def _nan_bound(bounded: Callable[[Any, Any], Any]) -> Callable[[Any, Any], Any]:
    """``bounded`` by a bound that may be NaN (a tensor's entry): NaN where it is, as torch's clamp."""
    return lambda p, q: ca.if_else(is_nan(q), q, bounded(p, q), False)


def _bound(bounded: Callable[[Any, Any], Any], bound: Any) -> Callable[[Any, Any], Any]:
    # a constant bound free of NaN (clamp(min=eps), the common one) needs no test of it
    if isinstance(bound, SymTensor) or np.isnan(constant(bound)).any():
        return _nan_bound(bounded)
    return bounded


def clamp(x, min=None, max=None):  # noqa: A002 (torch's names)
    """``min(max(x, min), max)`` as torch: each bound broadcast against the running result, slope 1 at a bound
    (and, with min > max, ``max`` everywhere); NaN where ``x`` or a bound is NaN."""
    y = as_float(lift(x))
    if min is not None:
        y = binary(_bound(_at_least, min), y, min)
    if max is not None:
        y = binary(_bound(_at_most, max), y, max)
    return y


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
