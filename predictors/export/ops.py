"""The torch operations the exporter maps to CasADi, each in the layout of ``predictors.export.symbolic``.

Every supported operation is a key of ``HANDLERS`` (functions, ``torch.Tensor`` operators) or ``METHODS``
(``x.reshape(...)``); anything else raises ``ExportError`` naming the operation and the module. Pure data
movement goes through ``gather_like`` on numpy's own index arithmetic; arithmetic is whole-matrix CasADi.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import casadi as ca
import torch
import torch.nn.functional as F

from predictors.export.attention import scaled_dot_product_attention
from predictors.export.elementwise import (
    add,
    binary,
    clamp,
    div,
    gelu,
    identity,
    leaky_relu,
    logical_not,
    mul,
    power,
    relu,
    sigmoid,
    softplus,
    sub,
    to,
    unary,
    where,
)
from predictors.export.errors import detach
from predictors.export.extremes import amax, amin, maximum, minimum, values_and_indices
from predictors.export.layers import (
    dropout,
    full_like,
    layer_norm,
    new_constant,
    new_full,
    ones_like,
    zeros_like,
)
from predictors.export.linalg import (
    all_true,
    any_true,
    cdist,
    einsum,
    linalg_norm,
    linear,
    log_softmax,
    matmul,
    mean,
    norm,
    normalize,
    reduce_sum,
    softmax,
    vector_norm,
)
from predictors.export.movement import (
    cat,
    chunk,
    expand,
    expand_as,
    flatten,
    getitem,
    narrow,
    permute,
    repeat,
    reshape,
    select,
    split,
    squeeze,
    stack,
    transpose,
    unbind,
    unsqueeze,
)
from predictors.export.symbolic import (
    HANDLERS,
    METHODS,
    SymTensor,
    as_float,
)


# ------------------------------------------------------------------------------------------------- tables
def _comparison(op):
    return lambda a, b: binary(op, a, b, is_bool=True)


def _logical(op):
    return lambda a, b: binary(lambda p, q: op(p != 0, q != 0), a, b, is_bool=True)


ELEMENTWISE: dict[str, Callable[[Any], Any]] = {
    "tanh": ca.tanh,
    "sigmoid": sigmoid,
    "relu": relu,
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
    "maximum": maximum,
    "minimum": minimum,
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


def register() -> None:
    """Enter every supported operation in the dispatch tables (idempotent: the tables are dicts)."""
    # Named operations: a method of SymTensor, and a handler for each owner that has one of that name
    # (only the element-wise ones are also in torch.nn.functional).
    tables: tuple[tuple[dict[str, Callable[..., Any]], tuple[Any, ...], Callable[..., Any] | None], ...] = (
        (ELEMENTWISE, (torch, torch.Tensor, F), unary),
        (BINARY, (torch, torch.Tensor), None),
        (SHAPING, (torch, torch.Tensor), None),
    )
    for table, owners, wrap in tables:
        for name, op in table.items():
            handler = wrap(op) if wrap is not None else op
            METHODS[name] = handler
            for owner in owners:
                if hasattr(owner, name):
                    HANDLERS[getattr(owner, name)] = handler
    for name, op in _operators().items():
        setattr(SymTensor, name, op)
        HANDLERS[getattr(torch.Tensor, name)] = op
    # after the named ones: these reuse the handler registered for torch.relu
    HANDLERS.update(_functions())
    METHODS.update(_methods())


def _operators() -> dict[str, Callable[..., Any]]:
    """Python's operators on tensors (``a + b``, ``x[i]``, ``a < b``); reflected ones swap the operands."""
    return {
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


def _functions() -> dict[Any, Callable[..., Any]]:
    """Torch functions and tensor methods outside the named tables, keyed by the callable itself."""
    return {
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
        torch.norm: norm,
        torch.Tensor.norm: norm,
        torch.linalg.norm: linalg_norm,
        torch.linalg.vector_norm: vector_norm,
        F.normalize: normalize,
        torch.cdist: cdist,
        torch.any: any_true,
        torch.all: all_true,
        torch.Tensor.any: any_true,
        torch.Tensor.all: all_true,
        torch.amax: amax,
        torch.amin: amin,
        torch.Tensor.amax: amax,
        torch.Tensor.amin: amin,
        torch.max: values_and_indices("torch.max(x, dim)", 1, torch.return_types.max),
        torch.min: values_and_indices("torch.min(x, dim)", -1, torch.return_types.min),
        torch.Tensor.max: values_and_indices("x.max(dim)", 1, torch.return_types.max),
        torch.Tensor.min: values_and_indices("x.min(dim)", -1, torch.return_types.min),
        torch.Tensor.detach: detach,
        torch.Tensor.contiguous: identity,
        torch.Tensor.clone: identity,
    }


def _methods() -> dict[str, Callable[..., Any]]:
    """Tensor methods beyond the named tables: conversions, copies, and constructors of new tensors."""
    return {
        "to": to,
        "float": lambda x: as_float(x),
        "double": lambda x: as_float(x),
        "bool": lambda x: to(x, torch.bool),
        "type_as": lambda x, other: to(x, other.dtype),
        "detach": detach,
        "contiguous": identity,
        "clone": identity,
        "new_zeros": new_constant(torch.zeros),
        "new_ones": new_constant(torch.ones),
        "new_full": new_full,
        "add": add,
        "relu": HANDLERS[torch.relu],
        "norm": norm,
        "any": any_true,
        "all": all_true,
        "amax": amax,
        "amin": amin,
        "max": values_and_indices("x.max(dim)", 1, torch.return_types.max),
        "min": values_and_indices("x.min(dim)", -1, torch.return_types.min),
    }
