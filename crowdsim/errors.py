"""Errors a user can cause through the simulator (bad scenario, bad sizes); the CLI prints them plainly."""


class SimulationError(ValueError):
    """Base class of the user-facing errors raised by `crowdsim`."""
