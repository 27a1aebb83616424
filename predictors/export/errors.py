"""The exporter's one error, and where in the net it happened (the path ``named_modules`` gives)."""

from __future__ import annotations

from typing import Any
from weakref import WeakKeyDictionary

from predictors.errors import PredictorError

# The module whose forward runs now, innermost last: pushed and popped by predictors.export.trace's hooks.
MODULE_STACK: list[str] = []
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


class ExportError(PredictorError):
    """A net cannot be exported: the operation and the module path, in one line."""

    def __init__(self, what: str, module: str):
        self.what = what
        self.module = module
        super().__init__(f"cannot export: {what} (in module {module!r})")

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        return type(self), (self.what, self.module)  # see predictors.errors.DatasetFormatError.__reduce__
