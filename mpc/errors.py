"""Errors a user can cause through the controller configuration or the compile cache's setting. Printed by the
CLI without a traceback."""


class MPCConfigError(ValueError):
    """An MPC configuration value outside its valid range, named with the value and what is expected.
    ``field``: the MPCConfig field refused, where one is (callers name where it was chosen, and whether a
    folder ran it before its bound)."""

    def __init__(self, message: str, field: str | None = None):
        super().__init__(message)
        self.field = field

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        return type(self), (str(self), self.field)


class CompileCacheError(RuntimeError):
    """The compile cache (mpc/compile_cache.py) cannot be used as asked (no compiler, a directory that is not
    one)."""


class CacheLocationError(CompileCacheError, MPCConfigError):
    """The cache directory cannot hold the cache (a file in its place, no write permission): a setting of the
    user's ($CROWDMPC_CACHE), which the command line prints as one line (an MPCConfigError)."""
