"""What a control step starts from, and what it falls back to when it cannot solve.

A solver failure (any status outside ``solvers.SOLVED``), a non-finite prediction, or running out of the
step's time budget never ends an episode. The step then applies, in order of preference:

1. ``"shifted"``: the last solved plan shifted by the steps elapsed since it was solved, as long as it still
   has actions that came out of a solve (a plan of horizon H covers H-1 further steps), clipped to Eq. 6
   from the current state;
2. ``"brake"``: decelerate every velocity component as hard as ``a_max`` allows.

The same shifted plan is the initial strategy ``u^(0)`` of the IBR loops and the warm start of the first
solve (primal and dual: multipliers are shifted the same way), which is why it lives here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from mpc.config import MPCConfig
from mpc.dynamics import braking, clip_to_bounds
from mpc.nlp import StepData

KINDS: Final[tuple[str, ...]] = ("shifted", "brake")  # Start.kind: what a fallback plan is


@dataclass(frozen=True)
class Start:
    """The initial strategy of a control step."""

    accels: np.ndarray  # (M, H, 2) u^(0): shifted previous plan (clipped to Eq. 6) or braking
    kind: str  # "shifted" or "brake": what applying ``accels`` means when no solve succeeds
    lam_x: np.ndarray | None  # (M, H, 2) shifted bound multipliers of the last solve, or None (cold start)
    lam_g: np.ndarray | None  # (M, H, 2) shifted velocity-constraint multipliers, or None

    def first_solve(self, iteration: int) -> dict[str, bool]:
        """How the IBR loops solve at ``iteration`` (from 1): the first solve of a step restarts from braking
        when stuck (``multi_start``), unless the step already starts from braking, where it asks both solvers
        instead (``explore``, mpc/solvers.py ``_Solver``); later solves do neither."""
        first = iteration == 1
        return {"restart": first and self.kind != "brake", "explore": first and self.kind == "brake"}


def heading_plan(data: StepData, cfg: MPCConfig) -> np.ndarray:
    """Controls ``(M, H, 2)`` that take every robot straight towards its Eq. 8 target, ignoring everyone else:
    at each step the acceleration (within ``a_max`` per component) towards the velocity of speed
    ``min(v_max, distance / dt)`` along the line to the target, then clipped to Eq. 6. A candidate initial
    strategy (``MPCConfig.dmpc_start``): like the shifted plan, DMPC applies it to a robot only if none of
    that robot's best responses improves on it by epsilon."""
    targets = data.reference_targets()
    positions = np.array(data.states[:, 0:2], dtype=float)
    velocities = np.array(data.states[:, 2:4], dtype=float)
    out = np.zeros((data.n_robots, cfg.horizon, 2))
    for k in range(cfg.horizon):
        offset = targets - positions
        distance = np.linalg.norm(offset, axis=1, keepdims=True)
        wanted = offset / np.maximum(distance, 1e-12) * np.minimum(cfg.v_max, distance / cfg.dt)
        out[:, k] = np.clip((wanted - velocities) / cfg.dt, -cfg.a_max, cfg.a_max)
        positions = positions + cfg.dt * velocities + 0.5 * cfg.dt**2 * out[:, k]
        velocities = velocities + cfg.dt * out[:, k]
    return clip_to_bounds(data.states, out, cfg.dt, cfg.v_max, cfg.a_max)


def shift(values: np.ndarray) -> np.ndarray:
    """Drop the first step of an ``(M, H, 2)`` array and append zeros (zero acceleration keeps velocity)."""
    return np.concatenate([values[:, 1:], np.zeros_like(values[:, :1])], axis=1)


class PlanMemory:
    """The plan applied at the previous step and how many of its actions came from a solve."""

    def __init__(self, cfg: MPCConfig):
        self.cfg = cfg
        self.reset()

    def reset(self) -> None:
        self._plan: np.ndarray | None = None  # (M, H, 2) whose first action was applied last step
        self._solved_actions = 0  # leading actions of _plan that came out of a solve
        self._lam_x: np.ndarray | None = None
        self._lam_g: np.ndarray | None = None

    def start(self, data: StepData) -> Start:
        """``u^(0)`` for this step: the previous plan shifted by one step, else braking."""
        cfg = self.cfg
        brake = braking(data.states, cfg.horizon, cfg.dt, cfg.a_max)
        parked = ~np.asarray(data.active, dtype=bool)
        if self._plan is None or self._solved_actions <= 1 or self._plan.shape[0] != data.n_robots:
            return Start(brake, "brake", None, None)
        accels = clip_to_bounds(data.states, shift(self._plan), cfg.dt, cfg.v_max, cfg.a_max)
        accels[parked] = brake[parked]
        lam_x = None if self._lam_x is None else shift(self._lam_x)
        lam_g = None if self._lam_g is None else shift(self._lam_g)
        return Start(accels, "shifted", lam_x, lam_g)

    def commit(
        self,
        applied_plan: np.ndarray,
        solved: bool,
        lam_x: np.ndarray | None = None,
        lam_g: np.ndarray | None = None,
        *,
        kind: str = "shifted",
    ) -> None:
        """Record the plan whose first action is applied now; ``solved``: it came out of this step's solve.
        ``kind``, for a plan that did not (``Start.kind``): the shifted previous plan, or braking."""
        if kind not in KINDS:
            raise ValueError(f"PlanMemory.commit: kind {kind!r} is none of {list(KINDS)}")
        if solved:
            self._solved_actions = self.cfg.horizon
            self._lam_x, self._lam_g = lam_x, lam_g
        elif kind == "brake":  # braking came out of no solve: no solved action, no multipliers to warm from
            self._solved_actions = 0
            self._lam_x = self._lam_g = None
        else:
            # The shifted previous plan: one solved action fewer, its multipliers shifted with it.
            self._solved_actions = max(self._solved_actions - 1, 0)
            if self._lam_x is not None:
                if self._lam_g is None:
                    raise RuntimeError(
                        "PlanMemory holds lam_x without lam_g: commit both multipliers or neither"
                    )
                self._lam_x, self._lam_g = shift(self._lam_x), shift(self._lam_g)
        self._plan = np.array(applied_plan, dtype=float)
