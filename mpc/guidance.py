"""Guidance around standing crowds: where Eq. 8's reference heads when the straight line to the goal is shut.

Why. Eq. 8's reference runs straight from the robot to its goal, and the horizon looks 1.6 s ahead: a robot
whose straight line crosses a row of humans standing closer together than ``2 d_min`` has no plan that makes
progress without entering their personal space, so the MPC stops in front of the row (a local minimum, not a
solver failure). In the paper's perpendicular crossing the humans stop on goals spread along ``x = +-5..6``;
robots that the crossing flow has pushed sideways end up behind that row. With safety margins this is how
episodes time out (``social_lstm_eth``, 8 humans, perpendicular, 40 episodes, margins ``fixed:0.1`` on every
step: all 6 timeouts ended with the whole flock 5-9 m from its goals, behind the humans' goal row).

What. Humans the caller considers standing are discs of radius ``clearance`` (``d_min`` plus their margin, or
the distance Eq. 11's soft penalty keeps: ``MPCConfig.standing_clearance``). A robot whose straight segment to
its goal stays clear of every disc keeps the goal as its target: its NLP is exactly the paper's. For a robot
whose segment is blocked, the shortest path around the discs is found on a visibility graph (nodes on a ring
around each disc, edges where the segment between two nodes clears every disc: the shortest path among discs
bends only at their boundaries), and the reference heads for that path's first corner, prolonged to
``lookahead`` (a step past what the horizon covers at ``v_max``, at least ``LOOKAHEAD``) so that the reference
keeps moving at ``v_max``, but no further than where the prolonged line would enter a disc (Eq. 8's reference
stops on its target; a prolongation into a disc led the reference through a human in 7 % of guided cases on
random scenes). A robot already inside a disc (pushed there, or held just inside by the soft penalty) keeps
that disc shrunk to just inside its own distance, so it is led round the human, not straight through it, and
guidance does not flip as the robot crosses the disc's edge. No path (a goal inside a disc, discs that close
the robot in): the goal, as without guidance.
"""

from __future__ import annotations

import heapq
import math
from typing import Final

import numpy as np

RING_NODES: Final[int] = 16  # nodes around each disc
RING_SCALE: Final[float] = 1.08  # ring radius / clearance: nodes sit just outside the disc
LOOKAHEAD: Final[float] = 2.0  # m, the target's distance at least: v_max (H + 1) tau with Table I's values
INSIDE_SHRINK: Final[float] = 0.99  # a disc around the robot: radius this fraction of the robot's distance


def segment_distances(a: np.ndarray, b: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``(E, K)``: the distance from each of ``points`` ``(K, 2)`` to each segment ``a[e] -> b[e]``."""
    a, b = np.atleast_2d(a)[:, None, :], np.atleast_2d(b)[:, None, :]
    ab = b - a
    length2 = np.maximum(np.sum(ab**2, axis=-1), 1e-18)
    t = np.clip(np.sum((points[None] - a) * ab, axis=-1) / length2, 0.0, 1.0)
    return np.linalg.norm(points[None] - (a + t[..., None] * ab), axis=-1)


def _shortest_first_corner(
    start: np.ndarray, goal: np.ndarray, discs: np.ndarray, clearance: float | np.ndarray
):
    """The first node after ``start`` on a shortest visibility-graph path to ``goal``, or None; ``clearance``
    the discs' radius, or one radius per disc.

    A* from the goal towards the start, the straight distance to the start as its heuristic (admissible and
    consistent, so the path is a shortest one, as Dijkstra's), and an edge tested for visibility only when
    it would shorten a path to its end node. Testing every edge first cost (16 K)^2 K segment-disc distances:
    0.5 s a robot among 50 mostly standing humans, 9 ms this way (CMPC, 3 robots, 50 humans: step p99 1.6 s
    before, 81 ms after, benchmarks/robot_scaling.py). Between equally short paths the first corner may
    differ from Dijkstra's."""
    radii = np.broadcast_to(np.asarray(clearance, dtype=float), (len(discs),))
    angles = np.linspace(0.0, 2 * math.pi, RING_NODES, endpoint=False)
    ring = RING_SCALE * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    nodes = (discs[:, None, :] + radii[:, None, None] * ring[None]).reshape(-1, 2)
    inside = (np.linalg.norm(nodes[:, None] - discs[None], axis=-1) < radii).any(axis=1)
    nodes = np.concatenate([start[None], goal[None], nodes[~inside]])
    to_start = np.linalg.norm(nodes - nodes[0], axis=1)
    dist = np.full(len(nodes), np.inf)  # from the goal (node 1); ``parent`` leads from a node towards it
    dist[1] = 0.0
    parent = np.full(len(nodes), -1)
    done = np.zeros(len(nodes), dtype=bool)
    frontier = [(to_start[1], 1)]
    while frontier:
        _, u = heapq.heappop(frontier)
        if done[u]:
            continue  # an outdated entry: u was reached more cheaply since
        if u == 0:
            return nodes[parent[0]]
        done[u] = True
        ends = np.flatnonzero(~done)
        through_u = dist[u] + np.linalg.norm(nodes[ends] - nodes[u], axis=1)
        shorter = through_u < dist[ends]
        ends, through_u = ends[shorter], through_u[shorter]
        if not len(ends):
            continue
        visible = segment_distances(np.repeat(nodes[u][None], len(ends), 0), nodes[ends], discs)
        clear = (visible >= radii).all(axis=1)
        for v, d in zip(ends[clear].tolist(), through_u[clear].tolist(), strict=True):
            dist[v], parent[v] = d, u
            heapq.heappush(frontier, (d + to_start[v], v))
    return None


def lookahead(v_max: float, horizon: int, dt: float) -> float:
    """How far, m, a guided target lies at least: one step beyond what Eq. 8's reference covers in the
    horizon at ``v_max``, so that the reference never stops short of the horizon's end. Table I's values
    (1 m/s, 4 steps of 0.4 s) give ``LOOKAHEAD``; a fixed 2 m stopped the reference of a 15-step horizon
    after 5 of its steps, and that of a 2 m/s robot halfway through its 3rd of 4."""
    return max(LOOKAHEAD, v_max * dt * (horizon + 1))


def guidance_targets(
    positions: np.ndarray,
    goals: np.ndarray,
    standing: np.ndarray,
    clearance: float,
    active: np.ndarray | None = None,
    reach: float = LOOKAHEAD,
) -> np.ndarray:
    """Eq. 8's target ``(M, 2)`` for each robot (module docstring): its goal, or where to head around the
    ``standing`` humans ``(K, 2)``, discs of radius ``clearance`` m. ``active``: the robots to guide (default
    all); ``reach``: the target's distance at least (``lookahead`` of the MPC's bounds and horizon), where
    the goal is further (``LOOKAHEAD`` always)."""
    positions, goals = np.asarray(positions, dtype=float), np.asarray(goals, dtype=float)
    targets = goals.copy()
    standing = np.asarray(standing, dtype=float).reshape(-1, 2)
    if not len(standing) or clearance <= 0:
        return targets
    active = np.ones(len(positions), dtype=bool) if active is None else np.asarray(active, dtype=bool)
    for r in np.flatnonzero(active):
        start, goal = positions[r], goals[r]
        # A disc the robot stands in is shrunk to just inside the robot (a robot on a human's centre has
        # none); a goal inside a disc cannot be reached without entering it, and then no detour helps.
        away = np.linalg.norm(standing - start, axis=1)
        radii = np.minimum(clearance, INSIDE_SHRINK * away)
        discs, radii = standing[radii > 1e-9], radii[radii > 1e-9]
        if not len(discs) or (np.linalg.norm(discs - goal, axis=1) < radii).any():
            continue
        if (segment_distances(start, goal, discs)[0] >= radii).all():
            continue
        corner = _shortest_first_corner(start, goal, discs, radii)
        if corner is None:
            continue
        heading = corner - start
        distance = float(np.linalg.norm(heading))
        if distance > 1e-9:
            direction = heading / distance
            # beyond LOOKAHEAD, no further than the goal is: a long horizon's reach must not send the
            # reference metres past a goal that a short detour reaches
            least = max(LOOKAHEAD, min(reach, float(np.linalg.norm(goal - start))))
            ahead = min(max(distance, least), _first_entry(start, direction, discs, radii, distance))
            targets[r] = start + direction * ahead
    return targets


def _first_entry(
    start: np.ndarray, direction: np.ndarray, discs: np.ndarray, radii: np.ndarray, beyond: float
) -> float:
    """How far along the ray ``start + t direction`` (unit) it first enters a disc at ``t >= beyond``
    (inf if never): the ray up to the corner at ``beyond`` is clear by construction."""
    offset = discs - start
    along = offset @ direction
    half_chord2 = along**2 - (np.sum(offset**2, axis=1) - radii**2)
    entry = along - np.sqrt(np.maximum(half_chord2, 0.0))
    hits = (half_chord2 > 0) & (entry >= beyond - 1e-9)
    return float(entry[hits].min()) if hits.any() else math.inf
