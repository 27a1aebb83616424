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
heads exactly back along that line (the cross products below are 0 up to rounding). Its Eq. 8 target then
moves ``NUDGE`` to its right, as two people meeting in a corridor keep right: the reflection symmetry is
gone and the robots pass right shoulder to right shoulder. Anything less than exact leaves the target alone,
so every scene the simulator draws (its starts and humans are random) is solved exactly as the paper's.
"""

from __future__ import annotations

from typing import Final

import numpy as np

NUDGE: Final[float] = 1e-3  # m to the right: far below any distance that matters, far above rounding
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


def keep_right(positions: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """``targets`` with each robot in an exact head-on tie (``head_on``) given a target ``NUDGE`` m to the
    right of its line; the same array, untouched, when no robot is."""
    tied = head_on(positions, targets)
    if not tied.any():
        return targets
    out = np.array(targets, dtype=float)
    heading = out[tied] - np.asarray(positions, dtype=float)[tied]
    unit = heading / np.linalg.norm(heading, axis=1, keepdims=True)
    out[tied] += NUDGE * np.stack([unit[:, 1], -unit[:, 0]], axis=1)  # (x, y) turned clockwise: right
    return out
