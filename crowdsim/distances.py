"""The distances between agents that the episode metrics are made of: the smallest at each recorded state
(robot-human, robot-robot, human-human), and the closest approach between states, every agent moving in a
straight line from one recorded position to the next (CrowdNav's ``point_to_segment_dist``).

Apart from crowdsim.metrics, which says what each metric means and turns these into an episode's figures:
pure geometry on position arrays, which the gym environment's reward (crowdsim.gym_reward) takes too.
"""

from __future__ import annotations

import math
from typing import cast

import numpy as np


def row_min_distance(a: np.ndarray, b: np.ndarray, present: np.ndarray | None = None) -> np.ndarray:
    """(T,) smallest centre distance at each row between agents of ``a (T, P, 2)`` and ``b (T, Q, 2)``, of
    ``b``'s agents only those ``present (T, Q)`` at the row (None: all)."""
    if a.shape[1] == 0 or b.shape[1] == 0:
        return np.full(len(a), math.inf)
    d = np.linalg.norm(a[:, :, None, :] - b[:, None, :, :], axis=-1)
    if present is not None:
        d = np.where(present[:, None, :], d, math.inf)
    return d.min(axis=(1, 2))


def row_min_within(positions: np.ndarray, present: np.ndarray | None = None) -> np.ndarray:
    """(T,) smallest centre distance at each row between two different agents of ``positions (T, P, 2)``
    (robots with robots, humans with humans), both ``present (T, P)`` there (None: all); inf with fewer
    than two agents."""
    if positions.shape[1] < 2:
        return np.full(len(positions), math.inf)
    d = np.linalg.norm(positions[:, :, None, :] - positions[:, None, :, :], axis=-1)
    if present is not None:
        d = np.where(present[:, :, None] & present[:, None, :], d, math.inf)
    iu = np.triu_indices(positions.shape[1], k=1)
    return cast(np.ndarray, d[:, iu[0], iu[1]].min(axis=1))


def closest_approach(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """``(...)`` smallest norm on the segment from ``start (..., 2)`` to ``end (..., 2)``: the closest
    approach of two agents whose relative position moves linearly from ``start`` to ``end``,
    ``min over s in [0, 1] of |start + s (end - start)|`` (CrowdNav's ``point_to_segment_dist``)."""
    d = end - start
    length2 = np.einsum("...k,...k->...", d, d)
    s = np.clip(-np.einsum("...k,...k->...", start, d) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    return np.linalg.norm(start + s[..., None] * d, axis=-1)


def _swept_min(rel: np.ndarray, present: np.ndarray | None = None) -> float:
    """Closest approach of the relative positions ``rel (T+1, ..., 2)`` of agent pairs, each moving
    linearly between its rows; the rows count too. ``present (T+1, ...)``: the pairs that exist at each row
    (None: all); a segment counts where its pair exists at both ends."""
    at_rows = np.linalg.norm(rel, axis=-1)
    if present is not None:
        at_rows = np.where(present, at_rows, math.inf)
    nearest = float(at_rows.min())
    if len(rel) < 2:
        return nearest
    swept = closest_approach(rel[:-1], rel[1:])
    if present is not None:
        swept = np.where(present[:-1] & present[1:], swept, math.inf)
    # np.minimum, not min(): a NaN (an infinite position) must show, not be dropped by argument order
    return float(np.minimum(nearest, swept.min()))


def min_distance_between_steps(
    robot_positions: np.ndarray, human_positions: np.ndarray, present: np.ndarray | None = None
) -> float:
    """Robot-human closest approach (m) of ``robot_positions (T+1, M, 2)`` and ``human_positions
    (T+1, N, 2)`` when every agent moves linearly between its recorded positions; the recorded states
    count too, so it is never above their minimum. ``present (T+1, N)``: the humans there at each row
    (a replayed crowd's; None: all). inf without a robot or a human."""
    if robot_positions.shape[1] == 0 or human_positions.shape[1] == 0:
        return math.inf
    rel = human_positions[:, None, :, :] - robot_positions[:, :, None, :]  # (T+1, M, N, 2)
    pairs = None if present is None else np.broadcast_to(present[:, None, :], rel.shape[:-1])
    return _swept_min(rel, pairs)


def min_robot_distance_between_steps(robot_positions: np.ndarray) -> float:
    """Robot-robot closest approach (m) of ``robot_positions (T+1, M, 2)``, as
    ``min_distance_between_steps`` takes robot-human; inf with fewer than two robots."""
    if robot_positions.shape[1] < 2:
        return math.inf
    first, second = np.triu_indices(robot_positions.shape[1], k=1)
    return _swept_min(robot_positions[:, second] - robot_positions[:, first])  # (T+1, pairs, 2)
