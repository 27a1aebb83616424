"""The exporter's one error, and where in the net it happened (the path ``named_modules`` gives)."""

from __future__ import annotations

from typing import Any
from weakref import WeakKeyDictionary

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


def unsupported(what: str) -> ExportError:
    """The refusal of an operation no dispatch table holds (``what``: "operation torch.sort"): the torch.nn
    layer it ran in where it ran in one, and where the supported operations are listed."""
    layer = LAYER_STACK[-1] if LAYER_STACK else None
    if layer is not None and layer.__module__.startswith("torch.nn."):
        what = f"{what}, inside torch.nn.{layer.__name__}, a layer the export does not map"
    return ExportError(f"unsupported {what}", current_module(), SUPPORTED_LIST)


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
