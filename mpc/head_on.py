"""Two robots meeting exactly head-on: the tie that Eq. 8's straight references cannot break.

Why. When two robots' straight lines to their goals run along one line towards each other (a swap of places
typed as exact coordinates, ``[-4, 0] -> [4, 0]`` and ``[4, 0] -> [-4, 0]``), every term of the NLPs is
symmetric under the reflection across that line, so the solvers' iterates never leave it: the paper's
penalty has no sideways gradient there. Measured with nobody else about (docs/extending.md, "Two robots
exactly head-on"): CMPC stopped the two robots facing each other 1.07 m apart until the time limit, and DMPC's
best responses carried them through each other (0.39 m between centres, bodies overlapping) and counted it
a success. Offsetting one robot's start by 1e-8 m was enough for both to pass on a side, so the tie is one
of floating point, not of the method.

What. A robot is in such a tie when a teammate stands exactly on its line to its target, ahead of it, and
heads exactly back along that line (the cross products below are 0 up to rounding), or when it is a
teammate's exact mirror image on a crossing path (``mirrored``: DMPC's Jacobi update keeps such a pair
mirrored). Its Eq. 8 target then moves ``NUDGE`` to its right for the step, as two people meeting in a
corridor keep right: the reflection symmetry is gone and the robots pass right shoulder to right shoulder.
Anything less than exact leaves the target alone, so every scene the simulator draws (its teams travel side
by side among random humans) is solved exactly as the paper's.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np

NUDGE: Final[float] = 0.03  # m to the right (1 mm: DMPC crossed 3.6 s slower; 0.1 m: 8 robots touched)
# |cross| / (|a| |b|), and a reflection's miss relative to the distances, below which a tie counts as exact:
# the ties above give 0 or ~1e-16
COLLINEAR: Final[float] = 1e-9
Point = tuple[float, float]


def _head_on(p: Point, t: Point, q: Point, u: Point) -> bool:
    """Robots at ``p`` and ``q`` bound for ``t`` and ``u`` meet head-on along one line: each heads along it
    towards the other, and their ways overlap (the two targets do not stop them short of each other).
    Scalar arithmetic with early exits: a few microseconds a pair, where numpy's calls on (M, M) arrays cost
    a tenth of a millisecond at every team size."""
    rx, ry = q[0] - p[0], q[1] - p[1]
    hx, hy = t[0] - p[0], t[1] - p[1]
    gx, gy = u[0] - q[0], u[1] - q[1]
    r, h, g = math.hypot(rx, ry), math.hypot(hx, hy), math.hypot(gx, gy)
    if abs(hx * ry - hy * rx) > COLLINEAR * h * r or hx * rx + hy * ry <= 0 or r > h + g:
        return False
    return abs(gx * ry - gy * rx) <= COLLINEAR * g * r and gx * rx + gy * ry < 0 < r


def _mirrored(p: Point, t: Point, v: Point, q: Point, u: Point, w: Point) -> bool:
    """The reflection across the perpendicular bisector of ``p`` and ``q`` takes target ``t`` to ``u`` and
    velocity ``v`` to ``w``, and the path from ``p`` to ``t`` crosses that bisector."""
    rx, ry = q[0] - p[0], q[1] - p[1]
    r = math.hypot(rx, ry)
    reach = math.hypot(t[0] - p[0], t[1] - p[1])
    if r == 0 or abs(reach - math.hypot(u[0] - q[0], u[1] - q[1])) > COLLINEAR * (r + reach):
        return False  # mirror images are as far from their targets
    nx, ny = rx / r, ry / r
    beyond = (t[0] - 0.5 * (p[0] + q[0])) * nx + (t[1] - 0.5 * (p[1] + q[1])) * ny
    if beyond <= 0:
        return False
    if math.hypot(t[0] - 2 * beyond * nx - u[0], t[1] - 2 * beyond * ny - u[1]) > COLLINEAR * (r + reach):
        return False
    along = v[0] * nx + v[1] * ny
    speeds = 1.0 + math.hypot(*v) + math.hypot(*w)
    return math.hypot(v[0] - 2 * along * nx - w[0], v[1] - 2 * along * ny - w[1]) <= COLLINEAR * speeds


def _points(array: np.ndarray) -> list[Point]:
    return [(float(x), float(y)) for x, y in np.asarray(array, dtype=float)]


def head_on(positions: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """``(M,)`` True for each robot whose line to its target runs exactly through a teammate ahead of it that
    heads exactly back along it, their ways overlapping. ``positions`` and ``targets`` are ``(M, 2)`` m."""
    p, t = _points(positions), _points(targets)
    tied = np.zeros(len(p), dtype=bool)
    for i in range(len(p)):
        for j in range(i + 1, len(p)):
            if _head_on(p[i], t[i], p[j], t[j]):
                tied[[i, j]] = True
    return tied


def mirrored(positions: np.ndarray, targets: np.ndarray, velocities: np.ndarray) -> np.ndarray:
    """``(M,)`` True for each robot that is a teammate's mirror image on crossing paths: the reflection across
    the perpendicular bisector of their positions takes its target and velocity exactly to the teammate's,
    and its line to its target crosses that bisector. Two robots crossing at right angles from the same
    distance are such a pair: DMPC's Jacobi update gives the two the same best response, mirrored, at every
    iteration (both dodge, both wait, both go), and in the closed loop they went through each other (0.19 m
    between centres; CMPC's joint solve crossed in 9.2 s)."""
    p, t, v = _points(positions), _points(targets), _points(velocities)
    tied = np.zeros(len(p), dtype=bool)
    for i in range(len(p)):
        for j in range(i + 1, len(p)):
            if _mirrored(p[i], t[i], v[i], p[j], t[j], v[j]):
                tied[[i, j]] = True
    return tied


def keep_right(
    positions: np.ndarray, targets: np.ndarray, velocities: np.ndarray | None = None
) -> np.ndarray:
    """``targets`` with each robot in an exact tie (``head_on``, or ``mirrored`` given ``velocities``) given
    a target ``NUDGE`` m to the right of its line; the same array, untouched, when no robot is."""
    tied = head_on(positions, targets)
    if velocities is not None:
        tied |= mirrored(positions, targets, velocities)
    if not tied.any():
        return targets
    out = np.array(targets, dtype=float)
    heading = out[tied] - np.asarray(positions, dtype=float)[tied]
    unit = heading / np.hypot(heading[:, :1], heading[:, 1:])  # hypot: no overflow of x^2 at 1e154 m
    out[tied] += NUDGE * np.stack([unit[:, 1], -unit[:, 0]], axis=1)  # (x, y) turned clockwise: right
    return out
