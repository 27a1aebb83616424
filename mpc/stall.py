"""Which robots are stalled: no progress towards their goals over a window, so flocking must not hold them.

Why. Eq. 15's flocking term pulls every pair of robots to ``d_flock``. When one robot of the flock is boxed in
(behind standing humans, in a gap narrower than twice its clearance) the others cannot leave it without
paying that term, and the whole flock stops: a deadlock of the potential, not of the solver. Measured with
``conformal-shortfall:0.05`` margins and guidance at 9 humans (`crowdmpc simulate --controller cmpc
--predictor social_lstm_eth --scenario perpendicular --humans 9 --seed 7 ...`): the three robots stood
within 1.3 m of each other from 20 s to the 40 s timeout, the free one's plan heading for its goal a few
centimetres a step and never applying it; with flocking off it left at once.

What. A robot is stalled when it has not arrived and its distance to its goal fell by less than
``progress`` m over the last ``window_s`` seconds (robots that have run for less than the window are never
stalled). Both distances are to the goal it has now: with goals as slots (crowdsim/slots.py) a robot's goal
can change, and a robot driving to a new slot is moving, one standing still is not. The controller drops
the flocking weight of every pair with a stalled robot (``StepData.flocking``)
until it moves again; everything else in the NLP is the paper's.
"""

from __future__ import annotations

from collections import deque
from typing import Final

import numpy as np

PROGRESS: Final[float] = 0.25  # m towards the goal within the window that counts as moving (MPCConfig)
NEVER_STEPS: Final[float] = 2.0**62  # a window longer than any episode (EnvConfig's 100000 steps at most)


class StallWatch:
    """Positions over the last ``window_s / dt`` steps; ``update`` says who is stalled."""

    def __init__(self, window_s: float, dt: float, progress: float = PROGRESS):
        if window_s <= 0 or dt <= 0 or progress <= 0:
            raise ValueError(f"window_s, dt and progress must be > 0, got {window_s}, {dt}, {progress}")
        # min: past ~7e307 s (0.4 s steps) window_s / dt is inf, which round() cannot make an int; a window of
        # 2**62 steps is as much a "never" as any longer one
        self.steps = max(1, round(min(window_s / dt, NEVER_STEPS)))
        self.progress = progress
        # Trimmed in ``update``, not through ``maxlen``, which must fit a C ssize_t: a window longer than any
        # episode (stall_release_s = 1e19 s, a valid "never") overflowed it.
        self._positions: deque[np.ndarray] = deque()

    def reset(self) -> None:
        self._positions.clear()

    def update(self, positions: np.ndarray, goals: np.ndarray, arrived: np.ndarray) -> np.ndarray:
        """Record this step's positions; ``(M,)`` True for the robots stalled now."""
        positions, goals = np.array(positions, dtype=float), np.asarray(goals, dtype=float)
        self._positions.append(positions)
        if len(self._positions) > self.steps + 1:
            self._positions.popleft()
        if len(self._positions) <= self.steps:
            return np.zeros(len(positions), dtype=bool)
        before = np.linalg.norm(self._positions[0] - goals, axis=1)
        progress = before - np.linalg.norm(positions - goals, axis=1)
        return (progress < self.progress) & ~np.asarray(arrived, dtype=bool)
