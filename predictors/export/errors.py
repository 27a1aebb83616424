"""The exporter's one error, and where in the net it happened (the path ``named_modules`` gives)."""

from __future__ import annotations

from typing import Any
from weakref import WeakKeyDictionary

from torch import nn

from predictors.errors import PredictorError

# The module whose forward runs now, innermost last: pushed and popped by predictors.export.trace's hooks.
MODULE_STACK: list[str] = []
# The class of each module on MODULE_STACK, pushed and popped with it: an operation that no table maps, met
# inside a torch.nn layer, is named with that layer, which the user wrote (nn.MultiheadAttention's forward
# calls torch.is_floating_point: the refusal named only that call and the module path).
LAYER_STACK: list[type] = []
SUPPORTED_LIST = "the supported operations are listed in docs/extending.md, section 1"
# The net a symbolic run traces now (trace.symbolic_run), and per net traced, the first module where that run
# met detach() of a symbolic tensor. The export maps detach() to the identity, CasADi having no stop-gradient,
# so its Jacobian differentiates through what torch's does not: the parity check names the module when the
# Jacobians then differ, where it said only "differs ... (Jacobians)".
TRACING: list[Any] = []
DETACHED: WeakKeyDictionary[Any, str] = WeakKeyDictionary()


def detach(x: Any, *args: Any, **kwargs: Any) -> Any:
    """``x.detach()`` on a symbolic tensor: ``x`` itself, where it was met kept in ``DETACHED``."""
    if TRACING:
        DETACHED.setdefault(TRACING[-1], current_module())
    return x


def current_module() -> str:
    return MODULE_STACK[-1] if MODULE_STACK else "<top>"


# The torch.nn layers whose forward the export replaces by a CasADi form (predictors.export.trace.REPLACED's
# keys, entered there), and the methods of theirs that run only to build or show a layer, not in forward.
MAPPED_LAYERS: set[type] = set()
NOT_IN_FORWARD = frozenset(
    {"__init__", "__setstate__", "_reset_parameters", "reset_parameters", "extra_repr"}
    | {"generate_square_subsequent_mask"}  # nn.Transformer's, called by the user to make a mask
)


def torch_layer(layer: type) -> type | None:
    """The torch.nn layer ``layer`` is or derives from (the first in its MRO; nn.Module does not count)."""
    for cls in layer.__mro__:
        if cls.__module__.startswith("torch.nn.") and cls is not nn.Module:
            return cls
    return None


def own_methods(layer: type, base: type) -> list[str]:
    """The methods of ``base`` (or its torch bases) that ``layer``, a subclass, overrides and torch's forward
    may call (``forward``, ``_sa_block`` ...): where there are none, ``layer`` runs ``base``'s forward."""
    names = {n for cls in base.__mro__[: base.__mro__.index(nn.Module)] for n in vars(cls)} - NOT_IN_FORWARD
    return sorted(
        n for n in names if callable(getattr(base, n, None)) and getattr(layer, n) is not getattr(base, n)
    )


def _inside(layer: type) -> tuple[str, str]:
    """Where an unsupported operation ran, when that is a torch.nn layer or a user's subclass of a mapped
    one, and what to do."""
    base = torch_layer(layer)
    if base is layer:
        # inside a mapped layer the user's code is a callable it was given (its activation), not the layer
        unmapped = "" if base in MAPPED_LAYERS else ", a layer the export does not map"
        return f", inside torch.nn.{base.__name__}{unmapped}", SUPPORTED_LIST
    # a user's net may derive from a torch.nn container (nn.Sequential): only a mapped layer's subclass is
    # named
    own = " and ".join(own_methods(layer, base)) if base is not None and base in MAPPED_LAYERS else ""
    if base is None or not own:  # the export maps a subclass that keeps all of torch's forward
        return "", SUPPORTED_LIST
    torch_name = f"torch.nn.{base.__name__}"
    return (
        f", inside {layer.__qualname__}, a subclass of {torch_name} with its own {own} (the export maps "
        "torch's own layer only)",
        f"keep {torch_name} itself as a submodule with your steps around it, or write them in the supported "
        "operations, listed in docs/extending.md, section 1",
    )


def unsupported(what: str) -> ExportError:
    """The refusal of an operation no dispatch table holds (``what``: "operation torch.sort"): the torch.nn
    layer (or a user's subclass of a mapped one) it ran in where it ran in one, and what to do."""
    layer = LAYER_STACK[-1] if LAYER_STACK else None
    inside, hint = ("", SUPPORTED_LIST) if layer is None else _inside(layer)
    return ExportError(f"unsupported {what}{inside}", current_module(), hint)


class ExportError(PredictorError):
    """A net cannot be exported: the operation and the module path, in one line."""

    def __init__(self, what: str, module: str, hint: str = ""):
        self.what = what
        self.module = module
        self.hint = hint  # what to do, after the module
        super().__init__(f"cannot export: {what} (in module {module!r})" + (f"; {hint}" if hint else ""))

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        # see predictors.errors.DatasetFormatError.__reduce__
        return type(self), (self.what, self.module, self.hint)
