"""Errors a user can cause through the simulator (bad scenario, bad sizes). Printed by the CLI without a traceback."""


class SimulationError(ValueError):
    """Base class of the user-facing errors raised by `crowdsim`."""
