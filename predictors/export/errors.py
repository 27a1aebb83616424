"""The exporter's one error, and where in the net it happened (the path ``named_modules`` gives)."""

from __future__ import annotations

from predictors.errors import PredictorError

# The module whose forward runs now, innermost last: pushed and popped by predictors.export.trace's hooks.
MODULE_STACK: list[str] = []


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
