"""What the controller knows at a control step besides the predictions: the NLPs' per-step inputs."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from mpc.config import MPCConfig
from mpc.head_on import keep_right

# The most a position (m), velocity (m/s) or acceleration (m/s^2) of StepData, or a predicted position
# (cmpc.finite_prediction), may be in magnitude. The NLPs square positions and velocities (Eqs. 7, 11, 12,
# 15): a velocity of 1e155 m/s (its square inf, and inf - inf = NaN in Eq. 11), a position of 1e300 or a
# predicted one at -1e308 made the gradient NaN at the start point, and a Fatrop solve, which has no
# wall-time limit, never returned. At 1e9 what the horizon reaches, 1e9 (1 + H dt) m, stays within what
# MPC_BOUNDS reach, a_max (H dt)^2 / 2 (dt a day, a_max 1000 m/s^2): with every bound together
# (delta at its least, 1e-40) the cost is at most 2e85, its gradient 7e80 and Hessian 2e76 (horizon 4; 3e90,
# 4e85 and 4e80 at 100), far from float64's 1.8e308 for the solvers' squares of them
# (tests/mpc/test_step_data.py). 1e9 m is a million km: the simulator's robots cover at most 8.6e6 m (a day
# at 100 m/s), the replayed crowds tens of metres, a UTM northing less than 1e7 m.
MAX_MAGNITUDE: Final[float] = 1e9
# StepData's fields of numbers: each column's quantity and unit, for the message that refuses one
_QUANTITIES: Final[dict[str, tuple[tuple[str, str], ...]]] = {
    "states": (("position", "m"),) * 2 + (("velocity", "m/s"),) * 2,
    "last_actions": (("last action", "m/s^2"),) * 2,
    "goals": (("goal", "m"),) * 2,
    "targets": (("target", "m"),) * 2,
}


@dataclass(frozen=True)
class StepData:
    """What the controller knows at time t, besides the predictions."""

    states: np.ndarray  # (M, 4) [s_x, s_y, v_x, v_y], m and m/s
    last_actions: np.ndarray  # (M, 2) m/s^2, applied at t-1 (Eq. 10)
    goals: np.ndarray  # (M, 2) m
    active: np.ndarray  # (M,) bool; False: controls pinned to braking (a robot parked on its goal)
    arrived: np.ndarray | None = None  # (M,) bool, has reached its goal: no flocking with it; None: all False
    # (H, N_h) m added to d_min for each human at each step (Eq. 11); None: cfg.human_margins for everyone
    human_margins: np.ndarray | None = None
    # (M, 2) m, where Eq. 8's reference heads (mpc/guidance.py); None: the goals (the paper)
    targets: np.ndarray | None = None
    # (M,) bool, the robots that flock (mpc/stall.py: a stalled robot does not); None: every robot
    flocking: np.ndarray | None = None
    # (M,) m added to delta in Eq. 7's weight (costs.Track.goal_slack, mpc/parked.py); None: 0 (the paper)
    goal_slack: np.ndarray | None = None

    def __post_init__(self) -> None:
        """Arrays of the shapes above, taken as float or bool arrays (lists too), else a ValueError naming the
        field: a one-robot ``arrived`` for three robots was stretched to all three by numpy's broadcasting
        (each treated as arrived), and a wrong shape failed deep in the NLP's parameters."""
        states = np.asarray(self.states, dtype=float)
        if states.ndim != 2 or states.shape[1:] != (4,) or not np.all(np.isfinite(states)):
            raise ValueError(
                f"states must be finite rows [s_x, s_y, v_x, v_y] of shape (M, 4), got {_what(states)}"
            )
        _check_magnitude("states", states)
        object.__setattr__(self, "states", states)
        m = len(states)
        for name, what in (
            ("last_actions", "finite accelerations"),
            ("goals", "finite positions"),
            ("targets", "finite positions"),
            ("active", "booleans"),
            ("arrived", "booleans"),
            ("flocking", "booleans"),
        ):
            self._check(name, what, (m, 2) if what.startswith("finite") else (m,))

    def _check(self, name: str, what: str, shape: tuple[int, ...]) -> None:
        """``name`` as an array of ``what`` (finite floats, or booleans) and ``shape``; an optional field
        (default None) may stay None."""
        value = getattr(self, name)
        if value is None and name in ("arrived", "targets", "flocking"):
            return
        finite = what.startswith("finite")
        array = np.asarray(value, dtype=float if finite else bool)
        if array.shape != shape or (finite and not np.all(np.isfinite(array))):
            raise ValueError(
                f"{name} must be {what} of shape {shape}, one per robot of states, got {_what(array)}"
            )
        if finite:
            _check_magnitude(name, array)
        object.__setattr__(self, name, array)

    @property
    def n_robots(self) -> int:
        return len(self.states)

    def flock_distances(self, d_flock: float) -> np.ndarray:
        """Eq. 15's d_ij per unordered pair (costs.pair_index order) under ``flock_distance = "goals"``:
        ``max(d_flock, ||g_i - g_j||)``, so that the flock's shape at its goals costs nothing."""
        return np.maximum(d_flock, self._goal_gaps())

    def _goal_gaps(self) -> np.ndarray:
        """``||g_i - g_j||`` per unordered pair, m, in costs.pair_index's (row-major) order."""
        goals = np.asarray(self.goals, dtype=float)
        i, j = np.triu_indices(self.n_robots, k=1)
        return np.linalg.norm(goals[i] - goals[j], axis=1)

    def floc_weights(self, w_floc: float, flock_range: float = 0.0) -> np.ndarray:
        """One flocking weight per unordered pair (costs.pair_index order): w_floc unless a robot of the pair
        has arrived, is pinned (a parked robot must not pull the flock, nor be pulled) or does not flock
        (``flocking``), or, with ``flock_range`` > 0, the pair's goals lie more than ``flock_range`` m apart
        (``MPCConfig.flock_range``: robots bound for separate places)."""
        free = np.asarray(self.active, dtype=bool)
        if self.arrived is not None:
            free = free & ~np.asarray(self.arrived, dtype=bool)
        if self.flocking is not None:
            free = free & np.asarray(self.flocking, dtype=bool)
        i, j = np.triu_indices(self.n_robots, k=1)  # row-major: pair_index's order
        pairs = free[i] & free[j]
        if flock_range > 0:
            pairs &= self._goal_gaps() <= flock_range
        return w_floc * pairs.astype(float)

    def goal_slacks(self) -> np.ndarray:
        """``goal_slack`` as the NLPs' ``(M,)`` parameter, zeros without it."""
        if self.goal_slack is None:
            return np.zeros(self.n_robots)
        slack = np.asarray(self.goal_slack, dtype=float)
        if slack.shape != (self.n_robots,) or not np.all(np.isfinite(slack) & (slack >= 0)):
            raise ValueError(f"goal_slack must be finite metres >= 0 of shape {(self.n_robots,)}")
        return slack

    def reference_targets(self) -> np.ndarray:
        """Eq. 8's targets ``(M, 2)``: ``targets``, else the goals; a robot in an exact tie with a teammate
        keeps right (mpc/head_on.py: head-on, or mirror images, which held robots at a standstill or took
        them through each other). Read-only, worked out once: DMPC's local NLPs ask for it at every solve."""
        cached = self.__dict__.get("_reference_targets")
        if cached is not None:
            return cached
        targets = self.goals if self.targets is None else self.targets
        targets = np.asarray(targets, dtype=float)
        if targets.shape != (self.n_robots, 2) or not np.all(np.isfinite(targets)):
            raise ValueError(
                f"targets must be finite positions of shape {(self.n_robots, 2)}, got {targets.shape}"
            )
        cached = np.array(keep_right(self.states[:, 0:2], targets, self.states[:, 2:4]))
        cached.flags.writeable = False
        object.__setattr__(self, "_reference_targets", cached)
        return cached

    def margins(self, cfg: MPCConfig, n_humans: int) -> np.ndarray:
        """The NLPs' margin parameters: ``human_margins`` row-major, else ``cfg.human_margin(k)`` for every
        human (all 0 in the paper's method)."""
        if self.human_margins is None:
            steps = [cfg.human_margin(k) for k in range(cfg.horizon)]
            return np.repeat(np.asarray(steps, dtype=float), n_humans)
        margins = np.asarray(self.human_margins, dtype=float)
        if margins.shape != (cfg.horizon, n_humans) or not np.all(np.isfinite(margins) & (margins >= 0)):
            raise ValueError(
                f"human_margins must be finite metres >= 0 of shape {(cfg.horizon, n_humans)}, got "
                f"{margins.shape}"
            )
        return margins.ravel()


def _what(array: np.ndarray) -> str:
    """An array refused by StepData: its shape, and how many of its values are not finite (a NaN velocity
    of the right shape read as a wrong shape: "got shape (3, 4)")."""
    bad = int(np.sum(~np.isfinite(array))) if array.dtype.kind == "f" else 0
    return f"shape {array.shape}" + (f" with {bad} non-finite entries" if bad else "")


def _check_magnitude(name: str, array: np.ndarray) -> None:
    """ValueError naming the first robot of field ``name`` (finite, of its shape) with a number beyond
    ``MAX_MAGNITUDE``, and what that number is."""
    beyond = np.abs(array) > MAX_MAGNITUDE
    if beyond.any():
        robot, column = (int(k) for k in np.argwhere(beyond)[0])
        quantity, unit = _QUANTITIES[name][column]
        raise ValueError(
            f"{name}: robot {robot}'s {quantity} {array[robot, column]:g} {unit} exceeds "
            f"{MAX_MAGNITUDE:g} in magnitude, the most the MPC takes (mpc.step_data.MAX_MAGNITUDE; far "
            "larger values overflow the NLP's squares)"
        )
