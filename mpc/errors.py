"""Errors a user can cause through the controller configuration. Printed by the CLI without a traceback."""


class MPCConfigError(ValueError):
    """An MPC configuration value outside its valid range, named with the value and what is expected."""
