"""Run a net's own methods on symbolic tensors and wrap the result as a ``casadi.Function``.

``export_function(net, method, inputs, outputs, name)`` calls ``method`` (e.g. ``net.decode_step``) with one
``SymTensor`` per input. While it runs, the recurrent cells (``nn.LSTMCell``, ``nn.GRUCell``, whose forward
calls fused kernels), ``nn.MultiheadAttention``, ``nn.TransformerEncoderLayer`` and ``nn.TransformerEncoder``
are replaced by their CasADi forms on this instance only, and a pair of global module hooks keeps the path of
the module that runs (``pool.embedding``), so that an unsupported operation is reported where it happens.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import casadi as ca
import torch
from torch import nn

from predictors.export.attention import multihead_attention
from predictors.export.elementwise import sigmoid
from predictors.export.errors import (
    LAYER_STACK,
    MAPPED_LAYERS,
    MODULE_STACK,
    TRACING,
    ExportError,
    current_module,
    own_methods,
    torch_layer,
)
from predictors.export.linalg import linear
from predictors.export.movement import squeeze, unsqueeze
from predictors.export.ops import register
from predictors.export.symbolic import SymTensor, Unexportable, lift
from predictors.export.transformer import (
    transformer,
    transformer_decoder,
    transformer_decoder_layer,
    transformer_encoder,
    transformer_encoder_layer,
)

register()  # the dispatch tables SymTensor consults, filled before anything is exported


@dataclass(frozen=True)
class TensorSpec:
    """One input of an exported function: its name, torch shape, and whether it is a mask (0/1)."""

    name: str
    shape: tuple[int, ...]
    is_bool: bool = False

    @property
    def size(self) -> int:
        size = 1
        for s in self.shape:
            size *= s
        return size


# ----------------------------------------------------------------------------------------- recurrent cells
def _cell_inputs(cell: nn.Module, x: Any) -> tuple[SymTensor, bool]:
    x = lift(x)
    if x.ndim not in (1, 2):
        raise ExportError(f"{type(cell).__name__} input of shape {x.shape_}", current_module())
    return (unsqueeze(x, 0), False) if x.ndim == 1 else (x, True)


def _gates(cell: nn.Module, x: SymTensor, h: SymTensor) -> tuple[Any, Any]:
    """``x W_ih^T + b_ih`` and ``h W_hh^T + b_hh`` as (rows, gates) matrices."""
    return (
        linear(x, cell.weight_ih, cell.bias_ih).m,  # type: ignore[arg-type]
        linear(h, cell.weight_hh, cell.bias_hh).m,  # type: ignore[arg-type]
    )


def _state(value: Any, rows: int, hidden: int, batched: bool) -> SymTensor:
    if value is None:
        return lift(torch.zeros(rows, hidden, dtype=torch.float64))
    value = lift(value)
    return value if batched else unsqueeze(value, 0)


def lstm_cell(cell: nn.LSTMCell, input: Any, hx: Any = None) -> tuple[SymTensor, SymTensor]:  # noqa: A002
    """``nn.LSTMCell`` (gate order i, f, g, o)."""
    x, batched = _cell_inputs(cell, input)
    d = cell.hidden_size
    rows = x.shape_[0]
    h = _state(None if hx is None else hx[0], rows, d, batched)
    c = _state(None if hx is None else hx[1], rows, d, batched)
    from_x, from_h = _gates(cell, x, h)
    gates = from_x + from_h
    i = sigmoid(gates[:, 0:d])
    f = sigmoid(gates[:, d : 2 * d])
    g = ca.tanh(gates[:, 2 * d : 3 * d])
    o = sigmoid(gates[:, 3 * d : 4 * d])
    c_new = SymTensor(f * c.m + i * g, (rows, d))
    h_new = SymTensor(o * ca.tanh(c_new.m), (rows, d))
    if not batched:
        return squeeze(h_new, 0), squeeze(c_new, 0)
    return h_new, c_new


def gru_cell(cell: nn.GRUCell, input: Any, hx: Any = None) -> SymTensor:  # noqa: A002
    """``nn.GRUCell`` (gate order r, z, n; the reset gate multiplies the hidden part, bias included)."""
    x, batched = _cell_inputs(cell, input)
    d = cell.hidden_size
    rows = x.shape_[0]
    h = _state(hx, rows, d, batched)
    from_x, from_h = _gates(cell, x, h)
    r = sigmoid(from_x[:, 0:d] + from_h[:, 0:d])
    z = sigmoid(from_x[:, d : 2 * d] + from_h[:, d : 2 * d])
    n = ca.tanh(from_x[:, 2 * d : 3 * d] + r * from_h[:, 2 * d : 3 * d])
    h_new = SymTensor((1 - z) * n + z * h.m, (rows, d))
    return h_new if batched else squeeze(h_new, 0)


# The layers whose forward is replaced by its CasADi form while traced: the recurrent cells call fused
# kernels, and nn.MultiheadAttention's, nn.TransformerEncoderLayer's and nn.TransformerEncoder's forwards
# ask their inputs what a symbolic tensor cannot answer (query.is_nested, torch.is_floating_point of a mask)
# to choose torch's fast path. A user's subclass is replaced as its torch layer only where it keeps all of
# torch's forward (``_form``); one with a forward of its own runs that.
REPLACED: dict[type[nn.Module], Callable[..., Any]] = {
    nn.LSTMCell: lstm_cell,
    nn.GRUCell: gru_cell,
    nn.MultiheadAttention: multihead_attention,
    nn.TransformerEncoderLayer: transformer_encoder_layer,
    nn.TransformerEncoder: transformer_encoder,
    nn.TransformerDecoderLayer: transformer_decoder_layer,
    nn.TransformerDecoder: transformer_decoder,
    nn.Transformer: transformer,
}
MAPPED_LAYERS.update(REPLACED)  # a refusal inside a subclass of one of them names it (errors.unsupported)


def _form(module: nn.Module) -> Callable[..., Any] | None:
    """The CasADi form that replaces ``module``'s forward: its class's, or its torch layer's where the class
    is a user's subclass that overrides none of the methods torch's forward calls (one that only adds
    attributes runs torch's forward, which a symbolic tensor cannot run); else None (its forward runs)."""
    layer = type(module)
    base = torch_layer(layer)
    if base is None or base not in REPLACED or (base is not layer and own_methods(layer, base)):
        return None
    return REPLACED[base]


# ----------------------------------------------------------------------------------------------- tracing
@contextmanager
def symbolic_run(net: nn.Module) -> Iterator[None]:
    """While inside: the net's cells and attention layers compute on SymTensors, and ``MODULE_STACK`` names
    the running module."""
    names = {id(module): name or type(net).__name__ for name, module in net.named_modules()}
    patched = []
    for module in net.modules():
        form = _form(module)
        if form is not None:
            module.forward = functools.partial(form, module)  # this instance only, removed below
            patched.append(module)

    def enter(module, args):
        MODULE_STACK.append(names.get(id(module), type(module).__name__))
        LAYER_STACK.append(type(module))

    def leave(module, args, output):
        if MODULE_STACK:
            MODULE_STACK.pop()
        if LAYER_STACK:
            LAYER_STACK.pop()

    pre = nn.modules.module.register_module_forward_pre_hook(enter)
    post = nn.modules.module.register_module_forward_hook(leave)
    MODULE_STACK.clear()
    MODULE_STACK.append(type(net).__name__)
    LAYER_STACK.clear()
    LAYER_STACK.append(type(net))
    TRACING.append(net)
    was_training = net.training
    net.eval()
    try:
        with torch.no_grad():
            yield
    finally:
        pre.remove()
        post.remove()
        MODULE_STACK.clear()
        LAYER_STACK.clear()
        TRACING.remove(net)
        for module in patched:
            del module.forward
        net.train(was_training)


def _traced(net: nn.Module, method: Callable[..., Any], tensors: Sequence[SymTensor]) -> Any:
    """``method(*tensors)`` inside ``symbolic_run``; torch code that fails on symbols (``torch.tensor`` of
    them, an index numpy refuses) is an ExportError naming the module, not the traceback of its internals."""
    with symbolic_run(net):
        try:
            return method(*tensors)
        except ExportError:
            raise
        except (RuntimeError, ValueError, TypeError, IndexError) as error:
            message = (str(error).strip().splitlines() or [""])[0][:200]
            raise ExportError(
                f"{type(error).__name__} while tracing ({message}): an operation the exporter does not "
                "support, or one that fails on these shapes",
                current_module(),
            ) from error


def _flat_output(value: Any, what: str) -> Any:
    if isinstance(value, Unexportable):  # the indices of x.max(dim), returned
        value.refuse()
    if isinstance(value, (SymTensor, torch.Tensor)):
        return lift(value).flat()
    raise ExportError(f"{what} is a {type(value).__name__}, not a tensor", current_module())


def export_function(
    net: nn.Module,
    method: Callable[..., Any],
    inputs: Sequence[TensorSpec],
    output_names: Sequence[str],
    name: str,
    *,
    symbol: Any = ca.MX,
) -> ca.Function:
    """``method(*inputs)`` as a CasADi function of the inputs' row-major flat vectors.

    ``method`` returns one tensor or a tuple of ``len(output_names)`` tensors; each becomes an output, its
    row-major flat vector. ``symbol`` is ``ca.MX`` (few large nodes: cheap to differentiate) or ``ca.SX``.
    """
    symbols = [symbol.sym(spec.name, spec.size) for spec in inputs]
    tensors = [
        SymTensor.from_flat(s, spec.shape, spec.is_bool) for s, spec in zip(symbols, inputs, strict=True)
    ]
    result = _traced(net, method, tensors)
    values = result if isinstance(result, tuple) else (result,)
    if len(values) != len(output_names):
        raise ExportError(
            f"{getattr(method, '__name__', 'the method')} returned {len(values)} values, expected "
            f"{len(output_names)} ({', '.join(output_names)})",
            type(net).__name__,
        )
    outputs = [_flat_output(v, n) for v, n in zip(values, output_names, strict=True)]
    return ca.Function(name, symbols, outputs, [s.name for s in inputs], list(output_names))


def output_shapes(
    net: nn.Module, method: Callable[..., Any], inputs: Sequence[TensorSpec]
) -> list[tuple[int, ...]]:
    """The shapes ``method`` returns for ``inputs`` (a symbolic run; nothing is built)."""
    tensors = [
        SymTensor.from_flat(ca.MX.sym(spec.name, spec.size), spec.shape, spec.is_bool) for spec in inputs
    ]
    result = _traced(net, method, tensors)
    values = result if isinstance(result, tuple) else (result,)
    return [tuple(lift(v).shape_) for v in values]
