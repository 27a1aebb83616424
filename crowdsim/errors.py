"""Errors a user can cause through the simulator (bad scenario, bad sizes); the CLI prints them plainly. And
the warning of a layout that runs but is probably not what was meant."""


class SimulationError(ValueError):
    """Base class of the user-facing errors raised by `crowdsim`."""


class LayoutWarning(UserWarning):
    """A layout the simulator runs but that starts agents in contact (``CrowdEnv.reset_layout``)."""


def too_crowded(human: int, n_humans: int, scenario: str, n_robots: int, draws: int) -> SimulationError:
    """The error of a layout whose rejection sampling ran dry (``human`` counts from 0)."""
    return SimulationError(
        f"could not place human {human + 1} of n_humans={n_humans} in scenario {scenario!r} with "
        f"{n_robots} robots after {draws} draws; use fewer agents"
    )
