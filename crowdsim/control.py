"""What a robot controller hands the closed loop each step.

It lives in the simulator package because the simulator's baselines produce it and ``crowdsim`` imports
nothing else from the project; ``pipelines.loop.controllers`` re-exports it for the MPC controllers.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class ControlOutput:
    """One control step's decision and what it cost to make it."""

    accelerations: np.ndarray  # (M, 2) m/s^2, the actions to apply now
    solve_time_s: float = 0.0  # wall time of the whole control step (prediction + all solves)
    status: str = "ok"  # solver status of the step ("ok" for the baselines)
    iterations: int = 0  # IBR iterations used (0 for the baselines)
    fallback: str | None = None  # None, or the fallback used: the MPCs' "shifted" (previous plan), "brake"
    potential: float | None = None  # F_t, Eq. (16), at the returned plan
    plan: np.ndarray | None = None  # (M, H, 2) planned robot positions at t+1..t+H
    # (H, N_h, 2) predicted human positions used by the final solve; a human all NaN was not predicted (out of
    # the controller's view: pipelines.loop.sensing)
    prediction: np.ndarray | None = None
    iteration_predictions: tuple[np.ndarray, ...] = ()  # (H, N_h, 2) per IBR iteration, when asked
    extra: dict[str, Any] = field(default_factory=dict)  # controller-specific numbers (JSON-serialisable)
