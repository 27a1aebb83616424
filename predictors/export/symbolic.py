"""``SymTensor``: a CasADi expression with a torch shape, which torch code runs on unchanged.

A net's own ``forward``/``encode``/``decode_step`` is executed with ``SymTensor`` inputs: torch hands every
function it cannot run on them to ``SymTensor.__torch_function__`` (the protocol ``torch.fx``'s proxies use),
and the table in ``predictors.export.ops`` maps each to CasADi. Unlike an fx proxy the shape is concrete,
so a net may unpack shapes and loop over the observed steps in Python; what it may not do is branch on a
value (``bool(x)``), which raises ``ExportError`` naming the module.

Layout: a tensor of shape ``(..., C)`` is the CasADi matrix ``(prod(...), C)``, its row-major 2-D view, so a
linear layer over any leading dims is one ``mtimes`` and elementwise operations are whole-matrix nodes. Data
movement (slicing, permutes, broadcasting, cat) is done on the row-major flat vector by a gather whose
indices are computed by applying the same numpy operation to ``arange`` (``gather_like``): numpy's own
semantics, no hand-written index arithmetic. Constants (parameters, ``zeros_like``) stay real torch tensors,
so torch folds them itself.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from typing import Any, NoReturn

import casadi as ca
import numpy as np
import torch

from predictors.export.errors import ExportError, current_module, unsupported

# torch function -> handler(*args, **kwargs); filled by predictors.export.ops (import order: ops imports us).
HANDLERS: dict[Any, Callable[..., Any]] = {}


def rows_cols(shape: tuple[int, ...]) -> tuple[int, int]:
    if not shape:
        return 1, 1
    return math.prod(shape[:-1]), shape[-1]


def _in_place(operator: str) -> Callable[..., Any]:
    def refuse(self, other):
        raise ExportError(
            f"in-place arithmetic x {operator} v: torch changes x and every view of it, which an exported "
            f"function cannot: write x = x {operator[:-1]} v",
            current_module(),
        )

    return refuse


class SymTensor:
    """A symbolic tensor: ``m`` is the CasADi (SX or MX) 2-D row-major view of a tensor of ``shape``."""

    __slots__ = ("m", "shape_", "is_bool")

    def __init__(self, m: Any, shape: tuple[int, ...], is_bool: bool = False):
        shape = tuple(int(s) for s in shape)
        if (m.shape[0], m.shape[1]) != rows_cols(shape):
            raise AssertionError(f"matrix {m.shape} does not hold a tensor of shape {shape}")
        self.m = m
        self.shape_ = shape
        self.is_bool = is_bool

    # --------------------------------------------------------------------------------- construction
    @classmethod
    def from_flat(cls, flat: Any, shape: tuple[int, ...], is_bool: bool = False) -> SymTensor:
        """From a row-major flat column (``tensor.reshape(-1)``)."""
        rows, cols = rows_cols(shape)
        return cls(ca.reshape(flat, cols, rows).T, shape, is_bool)

    def flat(self) -> Any:
        """The row-major flat column (``tensor.reshape(-1)``)."""
        return ca.vec(self.m.T)

    # --------------------------------------------------------------------------------- torch protocol
    @classmethod
    def __torch_function__(cls, func, types, args=(), kwargs=None):
        # torch asks the arguments' types in turn: the indices of x.max(dim) beside a symbolic tensor are
        # refused for what they are, not as an operation the tables lack
        found = first_unexportable((*args, *(kwargs or {}).values()))
        if found is not None:
            found.refuse()
        handler = HANDLERS.get(func)
        if handler is None:
            raise unsupported(f"operation {op_name(func)}")
        return handler(*args, **(kwargs or {}))

    # --------------------------------------------------------------------------------- shape queries
    @property
    def shape(self) -> torch.Size:
        return torch.Size(self.shape_)

    @property
    def ndim(self) -> int:
        return len(self.shape_)

    def dim(self) -> int:
        return len(self.shape_)

    def size(self, dim: int | None = None):
        return self.shape if dim is None else self.shape_[dim]

    def numel(self) -> int:
        return math.prod(self.shape_)

    def __len__(self) -> int:
        if not self.shape_:
            raise TypeError("len() of a 0-d tensor")
        return self.shape_[0]

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    @property
    def dtype(self) -> torch.dtype:
        return torch.bool if self.is_bool else torch.float64

    @property
    def device(self) -> torch.device:
        return torch.device("cpu")

    @property
    def requires_grad(self) -> bool:
        return False

    @property
    def T(self) -> SymTensor:  # noqa: N802 (torch's name)
        return call("permute", self, tuple(reversed(range(self.ndim))))

    @property
    def mT(self) -> SymTensor:  # noqa: N802 (torch's name)
        return call("transpose", self, -2, -1)

    # --------------------------------------------------------------------------------- values: refused
    def _value(self, what: str):
        raise ExportError(
            f"{what} of a symbolic tensor: the net branches on or reads a tensor's value, which an exported "
            "function cannot (use torch.where instead of if/else on values)",
            current_module(),
        )

    def __bool__(self):
        self._value("bool()")

    def __float__(self):
        self._value("float()")

    def __int__(self):
        self._value("int()")

    def __index__(self):
        self._value("using a tensor as an index")

    def item(self):
        self._value("item()")

    def tolist(self):
        self._value("tolist()")

    def numpy(self):
        self._value("numpy()")

    def __setitem__(self, key, value):
        raise ExportError(
            "in-place write x[...] = v: build the tensor with torch.cat, torch.stack or torch.where instead",
            current_module(),
        )

    # torch's x += v changes x itself, and so every view of it and every name bound to it; without these
    # Python would rebind x alone to x + v, a different graph from torch's
    __iadd__ = _in_place("+=")
    __isub__ = _in_place("-=")
    __imul__ = _in_place("*=")
    __itruediv__ = _in_place("/=")
    __ifloordiv__ = _in_place("//=")
    __imod__ = _in_place("%=")
    __ipow__ = _in_place("**=")
    __imatmul__ = _in_place("@=")
    __iand__ = _in_place("&=")
    __ior__ = _in_place("|=")
    __ixor__ = _in_place("^=")
    __ilshift__ = _in_place("<<=")
    __irshift__ = _in_place(">>=")

    def __getattr__(self, name: str):
        # Only reached for names this class lacks: in-place methods (add_, masked_fill_) and the rest.
        if name.startswith("__"):
            raise AttributeError(name)
        method = METHODS.get(name)
        if method is None:
            raise unsupported(tensor_member(name))
        return lambda *args, **kwargs: method(self, *args, **kwargs)

    __hash__ = object.__hash__

    def __repr__(self) -> str:
        return f"SymTensor(shape={self.shape_}, {'bool' if self.is_bool else 'float64'})"


# Tensor methods by name -> handler(self, *args, **kwargs); filled by predictors.export.ops.
METHODS: dict[str, Callable[..., Any]] = {}


class Unexportable:
    """What torch code gets in place of a value no exported function can give (the indices of
    ``x.max(dim)``): harmless while unused, and any use of it (a torch operation, arithmetic, indexing,
    reading it, returning it) refused with ``why``."""

    __slots__ = ("why",)

    def __init__(self, why: str):
        self.why = why

    def refuse(self, *args: Any, **kwargs: Any) -> NoReturn:
        raise ExportError(self.why, current_module())

    @classmethod
    def __torch_function__(cls, func, types, args=(), kwargs=None):
        found = first_unexportable((*args, *(kwargs or {}).values()))
        if found is None:  # torch calls this for an instance among the arguments, so it is there
            raise unsupported(f"operation {op_name(func)}")
        found.refuse()

    def __getattr__(self, name: str):
        if name.startswith("__"):  # copy's and pickle's probes, not a use
            raise AttributeError(name)
        self.refuse()

    __hash__ = object.__hash__

    def __repr__(self) -> str:
        return f"Unexportable({self.why!r})"


# Every operator and conversion Python or numpy may apply to a value, each a use of it.
for _name in (
    "add radd sub rsub mul rmul truediv rtruediv floordiv rfloordiv mod rmod pow rpow matmul rmatmul and "
    "rand or ror xor rxor neg pos invert abs lt le gt ge eq ne getitem iter len bool int float index array"
).split():
    setattr(Unexportable, f"__{_name}__", Unexportable.refuse)


def first_unexportable(values: Any) -> Unexportable | None:
    """The first ``Unexportable`` among ``values`` or in a list or tuple among them (``torch.cat([...])``)."""
    for value in values:
        if isinstance(value, Unexportable):
            return value
        if isinstance(value, (list, tuple)):
            found = first_unexportable(value)
            if found is not None:
                return found
    return None


def call(name: str, *args, **kwargs):
    return METHODS[name](*args, **kwargs)


_ABSENT = object()


def tensor_member(name: str) -> str:
    """``name`` as torch.Tensor holds it: "tensor attribute .is_nested" for a property (nn.MultiheadAttention
    reads query.is_nested: the refusal named it ".is_nested()", a call no one wrote), else "tensor method
    .cumsum()" (a name torch.Tensor lacks too, as before)."""
    found = inspect.getattr_static(torch.Tensor, name, _ABSENT)
    if found is not _ABSENT and not callable(found):
        return f"tensor attribute .{name}"
    return f"tensor method .{name}()"


def op_name(func: Any) -> str:
    module = getattr(func, "__module__", None) or ""
    qualname = getattr(func, "__qualname__", None) or getattr(func, "__name__", None) or repr(func)
    if module.startswith("torch._C") or module in ("", "builtins"):
        module = "torch"
    for prefix, public in (("TensorBase.", "Tensor."), ("_VariableFunctionsClass.", ""), ("_nn.", "")):
        if qualname.startswith(prefix):
            qualname = public + qualname.removeprefix(prefix)
    if module == "torch.functional":  # torch.norm, torch.split ...: the name the user wrote
        module = "torch"
    return f"{module}.{qualname}" if not qualname.startswith(module) else qualname


# ------------------------------------------------------------------------------------------------ helpers
def constant(value: Any) -> np.ndarray:
    """A real tensor, number or array as float64 numpy."""
    if isinstance(value, torch.Tensor):
        return value.detach().to("cpu", torch.float64).numpy()
    return np.asarray(value, dtype=np.float64)


def matrix_of(array: np.ndarray) -> ca.DM:
    rows, cols = rows_cols(array.shape)
    return ca.DM(np.ascontiguousarray(array, dtype=np.float64).reshape(rows, cols))


def lift(value: Any) -> SymTensor:
    """A SymTensor of ``value`` (a SymTensor already, or a constant)."""
    if isinstance(value, SymTensor):
        return value
    if isinstance(value, Unexportable):
        value.refuse()
    array = constant(value)
    is_bool = isinstance(value, torch.Tensor) and value.dtype == torch.bool
    return SymTensor(matrix_of(array), array.shape, is_bool)


def gather_like(x: SymTensor, index: np.ndarray, is_bool: bool | None = None) -> SymTensor:
    """The tensor whose element ``e`` is ``x``'s row-major element ``index[e]`` (``index`` has the result's
    shape). A gather that keeps whole columns is a 2-D index (rows, columns) of ``x.m``; any other a flat one.
    """
    index = np.asarray(index, dtype=np.int64)
    is_bool = x.is_bool if is_bool is None else is_bool
    shape = index.shape
    if shape == x.shape_ and np.array_equal(index.ravel(), np.arange(index.size)):
        return x
    in_cols = rows_cols(x.shape_)[1]
    rows, cols = rows_cols(shape)
    if not index.size:  # an empty slice (x[..., :0]): nothing to gather, and no first row or column to read
        return SymTensor(type(x.m)(rows, cols), shape, is_bool)
    grid = index.reshape(rows, cols)
    row_of, col_of = np.divmod(grid, in_cols)
    if (row_of == row_of[:, :1]).all() and (col_of == col_of[:1, :]).all():
        row_list = row_of[:, 0].tolist()
        col_list = col_of[0].tolist()
        if row_list == list(range(x.m.shape[0])) and col_list == list(range(in_cols)):
            return SymTensor(x.m, shape, is_bool)
        return SymTensor(x.m[row_list, col_list], shape, is_bool)
    return SymTensor.from_flat(x.flat()[grid.ravel().tolist()], shape, is_bool)


def arange_of(x: SymTensor) -> np.ndarray:
    return np.arange(x.numel(), dtype=np.int64).reshape(x.shape_)


def broadcast_to(x: SymTensor, shape: tuple[int, ...]) -> SymTensor:
    """``x`` expanded to ``shape`` (numpy broadcasting); a scalar stays (1, 1) for CasADi to broadcast."""
    if x.shape_ == tuple(shape):
        return x
    return gather_like(x, np.broadcast_to(arange_of(x), shape))


def as_float(x: SymTensor) -> SymTensor:
    return SymTensor(x.m, x.shape_, False) if x.is_bool else x
