"""The motion class of each human as the controller observes them, which the per-class margins
(``conformal-motion``, ``conformal-shortfall``; pipelines.loop.margins) plan with: from the humans' last
positions and how many of them were observed (``Observation.human_observed``, checked here)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from pipelines.errors import PipelineError

if TYPE_CHECKING:
    import numpy as np

    from crowdsim.env import Observation


def observed_classes(obs: Observation) -> np.ndarray:
    """The ``MOTION_CLASSES`` index ``(N_h,)`` of ``obs``'s humans from what the controller observes: their
    last ``CLASS_WINDOW`` positions (fewer where the simulator keeps fewer), ``obs.human_observed`` of them
    seen (None: ``obs.step + 1`` for all). A tracker's human who entered late has a padded past: counted as
    seen since the start it was classed "standing" or "slow", with their small margins, not "new"."""
    from predictors.conformal_classes import CLASS_WINDOW, motion_classes

    observed = human_observed(obs)
    seen: int | np.ndarray = obs.step + 1 if observed is None else observed
    return motion_classes(obs.history[-CLASS_WINDOW:, obs.n_robots :], seen, obs.dt)


def human_observed(obs: Observation) -> np.ndarray | None:
    """``obs.human_observed`` checked: ``(N_h,)`` ints >= 1 (the current position is an observation), else
    a PipelineError saying what it must be; None stays None (the simulator's: ``step + 1`` for everyone)."""
    import numpy as np

    if obs.human_observed is None:
        return None
    seen = np.asarray(obs.human_observed)
    if seen.shape != (obs.n_humans,) or not np.issubdtype(seen.dtype, np.integer):
        raise PipelineError(
            f"obs.human_observed must be {obs.n_humans} ints, one per human (positions observed), got "
            f"{seen.dtype} of shape {seen.shape}"
        )
    if (seen < 1).any():
        raise PipelineError(
            f"obs.human_observed must be >= 1 for every human (the current position is observed), got "
            f"{int(seen.min())} for human {int(np.argmin(seen))}"
        )
    return seen
