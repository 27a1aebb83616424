"""The robots' double integrator, Eq. 2, on CasADi symbols and (through the same code) on numbers.

Layout: a robot's state is ``x = [s_x, s_y, v_x, v_y]``; a control sequence over the horizon is a ``(2, H)``
matrix whose column ``k`` is ``a_{t+k}``; the resulting positions and velocities are ``(2, H)`` matrices whose
column ``k`` is the value at ``t+k+1``. Column-major ``(2, H)`` blocks are what ``reshape`` of a flat
``(H, 2)`` row-major plan gives in CasADi, so the NLPs slice them without copies.
"""

from __future__ import annotations

from typing import TypeAlias

import casadi as ca
import numpy as np

# CasADi is checked as untyped (see pyproject.toml), so this alias is Any to mypy; it documents intent.
Symbolic: TypeAlias = ca.SX | ca.MX | ca.DM


def step(state: Symbolic, accel: Symbolic, dt: float) -> Symbolic:
    """Eq. 2: ``s+ = s + dt v + dt^2 a / 2``, ``v+ = v + dt a``; state ``(4, 1)``, accel ``(2, 1)``."""
    s, v = state[0:2], state[2:4]
    return ca.vertcat(s + dt * v + 0.5 * dt**2 * accel, v + dt * accel)


def rollout(state: Symbolic, accels: Symbolic, dt: float) -> tuple[Symbolic, Symbolic]:
    """Positions and velocities ``(2, H)`` at ``t+1..t+H`` from state ``(4, 1)`` and controls ``(2, H)``.

    ``H`` applications of :func:`step`, so Eq. 2 is written once.
    """
    states = []
    for k in range(accels.shape[1]):
        state = step(state, accels[:, k], dt)
        states.append(state)
    trajectory = ca.horzcat(*states)
    return trajectory[0:2, :], trajectory[2:4, :]


def rollout_numpy(states: np.ndarray, accels: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised twin of :func:`rollout` for many robots: states ``(M, 4)``, accels ``(M, H, 2)``.

    Returns positions and velocities ``(M, H, 2)``. Used on the hot path (warm starts, DMPC bookkeeping)
    where building CasADi matrices would cost more than the arithmetic; a test checks it against
    :func:`rollout`.
    """
    states = np.asarray(states, dtype=float)
    accels = np.asarray(accels, dtype=float)
    velocities = states[:, None, 2:4] + dt * np.cumsum(accels, axis=1)
    previous_v = np.concatenate([states[:, None, 2:4], velocities[:, :-1]], axis=1)
    steps = dt * previous_v + 0.5 * dt**2 * accels
    positions = states[:, None, 0:2] + np.cumsum(steps, axis=1)
    return positions, velocities


def braking(states: np.ndarray, horizon: int, dt: float, a_max: float) -> np.ndarray:
    """Controls ``(M, H, 2)`` that bring each robot to rest as fast as the bound ``|a| <= a_max`` allows.

    Each component decelerates independently (Eq. 6 bounds components, not the norm), so the result stays
    within the bounds and never reverses a velocity component.
    """
    v = np.asarray(states, dtype=float)[:, 2:4].copy()
    out = np.zeros((len(v), horizon, 2))
    for k in range(horizon):
        a = np.clip(-v / dt, -a_max, a_max)
        out[:, k] = a
        v = v + dt * a
    return out


def clip_to_bounds(
    states: np.ndarray, accels: np.ndarray, dt: float, v_max: float, a_max: float
) -> np.ndarray:
    """``accels`` ``(M, H, 2)`` changed as little as possible (per step, per component) to satisfy Eq. 6.

    A velocity already beyond ``v_max`` is brought back as fast as ``a_max`` allows. Used to make a shifted
    previous plan a feasible initial strategy ``u^(0)``.
    """
    v = np.asarray(states, dtype=float)[:, 2:4].copy()
    out = np.empty_like(np.asarray(accels, dtype=float))
    for k in range(out.shape[1]):
        low = np.maximum((-v_max - v) / dt, -a_max)
        high = np.minimum((v_max - v) / dt, a_max)
        a = np.clip(accels[:, k], np.minimum(low, a_max), np.maximum(high, -a_max))
        out[:, k] = a
        v = v + dt * a
    return out
