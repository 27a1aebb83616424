"""Goals as slots of a formation (``EnvConfig.goal_assignment = "slots"``): which robot takes which goal.

The paper gives robot ``i`` goal ``i`` for the whole episode (``"fixed"``, the default). With many robots
that task is decided by arrival order as much as by the controller: when a crowd turns the flock, robots
arrive out of order, and a late robot must pass between teammates parked on goals 1.2 m apart, pushing them
off (benchmarks/robot_scaling.py's failure column: 14 of 16 failed CMPC episodes at 12 robots).

For interchangeable robots the natural task is to fill the goal formation. Here the simulator keeps the
matching of robots to goals that minimises the total squared distance, as in concurrent assignment and
planning of trajectories (CAPT; Turpin, Michael and Kumar, IJRR 2014): with straight paths that matching
never makes two robots' paths cross, so nobody has to pass a parked teammate, whose slot goes to the robot
coming in while it moves on to the next free one. Every step, after the agents move, the matching is solved
again (``scipy.optimize.linear_sum_assignment``) and replaces the current one only if it lowers the total by
more than ``SLOT_HYSTERESIS`` (m^2): near-ties would otherwise swap two robots' goals back and forth between
steps. Robots report the goal they hold now (``Observation.robot_goals``); success is judged on the matching
in force, which, for robots within ``radius`` of distinct goals, is that one.
"""

from __future__ import annotations

from typing import Final, Literal

import numpy as np
from scipy.optimize import linear_sum_assignment

GoalAssignment = Literal["fixed", "slots"]
GOAL_ASSIGNMENTS: Final[tuple[GoalAssignment, ...]] = ("fixed", "slots")
# m^2 by which a new matching must lower the total squared distance to replace the current one, so that a
# near-tie (a robot about halfway between two goals) does not swap goals back and forth every step. The only
# value measured (benchmarks/robot_scaling.py --goals slots); it is small against the 1.44 m^2 of one
# neighbouring slot.
SLOT_HYSTERESIS: Final[float] = 0.05


def match_slots(positions: np.ndarray, goals: np.ndarray, hysteresis: float = SLOT_HYSTERESIS) -> np.ndarray:
    """The permutation ``order`` such that robot ``i`` takes ``goals[order[i]]``: the identity unless the
    matching of least total squared distance beats the current one (robot ``i`` on ``goals[i]``) by more
    than ``hysteresis``."""
    positions = np.asarray(positions, dtype=float)
    goals = np.asarray(goals, dtype=float)
    if positions.shape != goals.shape or positions.ndim != 2 or positions.shape[1] != 2:
        raise ValueError(f"positions and goals must both be (M, 2), got {positions.shape} and {goals.shape}")
    identity = np.arange(len(goals))
    if len(goals) < 2:
        return identity
    cost = ((positions[:, None, :] - goals[None, :, :]) ** 2).sum(axis=-1)
    rows, order = linear_sum_assignment(cost)
    # rows is 0..M-1 in order for a square matrix.
    if cost[rows, order].sum() < np.trace(cost) - hysteresis:
        return order
    return identity
