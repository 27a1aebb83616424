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

from typing import Final

import numpy as np

NUDGE: Final[float] = 0.03  # m to the right (1 mm: DMPC crossed 3.6 s slower; 0.1 m: 8 robots touched)
# |cross| / (|a| |b|) below which two directions count as one line: the exact ties above give 0 or ~1e-16
COLLINEAR: Final[float] = 1e-9


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def head_on(positions: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """``(M,)`` True for each robot whose line to its target runs exactly through a teammate ahead of it that
    heads exactly back along it. ``positions`` and ``targets`` are ``(M, 2)`` m."""
    positions, targets = np.asarray(positions, dtype=float), np.asarray(targets, dtype=float)
    heading = targets - positions  # (M, 2)
    offset = positions[None, :, :] - positions[:, None, :]  # [i, j]: from robot i to robot j
    size = np.linalg.norm(heading, axis=1)
    scale = size[:, None] * np.linalg.norm(offset, axis=2)  # [i, j]
    on_line = np.abs(_cross(heading[:, None, :], offset)) <= COLLINEAR * scale
    ahead = np.einsum("ik,ijk->ij", heading, offset) > 0  # j in front of i
    towards = np.einsum("jk,ijk->ij", heading, offset) < 0  # j heads back towards i
    # j's line runs through i too: on_line[j, i] (offset[j, i] = -offset[i, j])
    tie = on_line & on_line.T & ahead & towards & (scale > 0)
    return tie.any(axis=1)


def mirrored(positions: np.ndarray, targets: np.ndarray, velocities: np.ndarray) -> np.ndarray:
    """``(M,)`` True for each robot that is a teammate's mirror image on crossing paths: the reflection across
    the perpendicular bisector of their positions takes its target and velocity exactly to the teammate's,
    and its line to its target crosses that bisector. Two robots crossing at right angles from the same
    distance are such a pair: DMPC's Jacobi update gives the two the same best response, mirrored, at every
    iteration (both dodge, both wait, both go), and in the closed loop they went through each other (0.19 m
    between centres; CMPC's joint solve crossed in 9.2 s)."""
    positions, targets = np.asarray(positions, dtype=float), np.asarray(targets, dtype=float)
    velocities = np.asarray(velocities, dtype=float)
    tied = np.zeros(len(positions), dtype=bool)
    for i, j in zip(*np.triu_indices(len(positions), k=1), strict=True):
        axis = positions[j] - positions[i]
        length = float(np.linalg.norm(axis))
        if length == 0:
            continue
        n = axis / length
        middle = 0.5 * (positions[i] + positions[j])
        reach = float(np.linalg.norm(targets[i] - positions[i]))
        crosses = float(np.dot(targets[i] - middle, n)) > 0  # robot i starts on the bisector's -n side
        target = targets[i] - 2 * np.dot(targets[i] - middle, n) * n
        velocity = velocities[i] - 2 * np.dot(velocities[i], n) * n
        speeds = float(np.linalg.norm(velocities[i]) + np.linalg.norm(velocities[j]))
        same = np.linalg.norm(target - targets[j]) <= COLLINEAR * (length + reach)
        if crosses and same and np.linalg.norm(velocity - velocities[j]) <= COLLINEAR * (1.0 + speeds):
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
    unit = heading / np.linalg.norm(heading, axis=1, keepdims=True)
    out[tied] += NUDGE * np.stack([unit[:, 1], -unit[:, 0]], axis=1)  # (x, y) turned clockwise: right
    return out
