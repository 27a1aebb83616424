"""How hard a robot that has reached its goal holds it (``MPCConfig.on_goal="yield"``).

Why. Eq. 7 weights a robot's goal term by ``1 / (||s_t - s_goal|| + delta)``: 1e4 on the goal, 10 / D for a
teammate D metres from its own. Robots parked on a formation's goals 1.2 m apart then wall off every goal
between them (passing needs about 2 x 1.03 m, where the Eq. 12 penalty fades), and a teammate that arrives
late, or was pushed off its goal, waits in front of the wall until the time limit: at 12 robots and 7 humans
most failed episodes ended so (``benchmarks/robot_scaling.py``; docs/results.md has the figures).

The rule. A parked robot holds its goal no harder than the farthest teammate still on its way pulls towards
its own: its Eq. 7 weight is ``w_goal / (max(||s_i - g_i||, D) + delta)``, D the largest distance to its
goal of a robot not within its radius of it (0 when every robot is: nothing to yield to). It enters the NLPs
as ``StepData.goal_slack = max(0, D - ||s_i - g_i||)``, added to delta. The weight is continuous in the
robot's own distance (no switching as a pushed robot leaves its radius). It switches once, by design, in its
teammates' distances: when the last robot away comes within its radius, D falls from at least the radius to 0
and every parked robot holds its goal at the paper's weight again (a parameter set between control steps, so
the NLPs see no discontinuity).
"""

from __future__ import annotations

import numpy as np


def yield_slack(positions: np.ndarray, goals: np.ndarray, reached: np.ndarray, radius: float) -> np.ndarray:
    """``(M,)`` m added to delta in Eq. 7's weight: ``max(0, D - d_i)`` for a robot that has reached its goal,
    0 for the others (module docstring); ``positions``, ``goals`` ``(M, 2)`` m, ``reached`` ``(M,)`` bool."""
    distances = np.linalg.norm(np.asarray(positions, float) - np.asarray(goals, float), axis=1)
    away = distances >= radius
    farthest = float(distances[away].max()) if away.any() else 0.0
    return np.where(np.asarray(reached, dtype=bool), np.maximum(0.0, farthest - distances), 0.0)
