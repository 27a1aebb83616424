"""Errors a user can cause through the pipelines (bad files, bad options). Printed without a traceback."""


class PipelineError(ValueError):
    """Base class of the user-facing errors raised by `pipelines`."""
