"""Optimal reciprocal collision avoidance (van den Berg, Guy, Lin, Manocha, "Reciprocal n-body collision
avoidance", 2011), following the reference RVO2 library (``Agent::computeNewVelocity``,
``linearProgram1/2/3``).

What matches RVO2
-----------------
* Neighbours: the ``max_neighbors`` nearest other agents strictly within ``neighbor_dist``, sorted by
  distance (the order in which RVO2's ``insertAgentNeighbor`` keeps them); the ORCA lines are built in that
  order, which matters to the incremental linear programs.
* One ORCA half-plane per neighbour: the velocity obstacle truncated by ``time_horizon`` (projection of the
  relative velocity on the cut-off circle or on a leg), reciprocal 1/2 responsibility
  (``point = v + u / 2``), and, for agents that already overlap, the cut-off circle of the simulation time
  step.
* The incremental 2-D linear program on the max-speed disc (closest point to the preferred velocity), and the
  3-D linear program (minimise the largest violation) when the 2-D one is infeasible (``crowdsim.orca_lp``).

Deviations, all outside the behaviour one can observe in a crowd
----------------------------------------------------------------
* float64 instead of RVO2's float32; the same ``RVO_EPSILON = 1e-5`` for parallel lines.
* No static obstacles (the scenarios have none), so there are no obstacle lines and ``time_horizon_obst`` is
  not a parameter.
* Two agents whose relative velocity equals exactly ``relative position / time step`` while overlapping give
  RVO2 a 0/0 (NaN velocity); here that measure-zero case uses the line through the current velocity
  perpendicular to the two centres (push apart), so a simulation never produces NaN. Two agents at the very
  same point have no line of centres: the lower index is pushed towards +x and the higher towards -x.

Neighbour geometry and the half-planes of every agent are computed at once with numpy broadcasting; only the
linear programs, which are sequential by nature, run per agent in plain Python floats (faster than numpy
scalars for a handful of lines). Agents whose preferred velocity already satisfies every half-plane (the
2-D program's first pass changes nothing) are resolved in numpy without entering Python at all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np

from crowdsim.errors import SimulationError, got, real_number, refuse_bools, seconds, whole_number
from crowdsim.orca_lp import lp2, lp3
from crowdsim.world import LEAST, MIN_DT, MOST_COORDINATE

# neighbor_dist is squared (1e300 overflowed the first step): a finite one up to 1000 km, far beyond any
# crowd; inf, every agent a neighbour, works as it is (inf squared is inf).
MAX_NEIGHBOR_DIST: Final[float] = 1e6  # m
# Its least: the world's least length. "> 0" took 5e-324, whose square is 0 (so no agent was ever a
# neighbour, as at any distance below the closest approach) and which the records then held. Checked as a run
# starts and by orca_velocities, not by OrcaParams, so that a sweep folder that ran one still reads back.
LEAST_NEIGHBOR_DIST: Final[float] = LEAST["radius"][0]  # m
# 1 / time_horizon scales the relative positions: 1e-305 s overflowed the velocity obstacles to inf (and
# gave velocities pointing away from the goal). A microsecond is far below any horizon (CrowdNav: 5 s).
MIN_TIME_HORIZON: Final[float] = 1e-6  # s
# The CLI's bound too (pipelines.config.keys.MOST): a crowd has at most crowdsim.scenarios.MAX_HUMANS people.
MAX_NEIGHBORS: Final[int] = 1000


@dataclass(frozen=True)
class OrcaParams:
    """RVO2 agent parameters as CrowdNav sets them for its ORCA pedestrians (``policy/orca.py``)."""

    neighbor_dist: float = 10.0  # m, only agents strictly closer than this are neighbours
    max_neighbors: int = 10  # the nearest this many neighbours get a half-plane
    time_horizon: float = 5.0  # s, velocity obstacles are truncated at this horizon

    def __post_init__(self):
        # frozen: the checked values are stored back, numpy's scalars as Python's
        dist = real_number(
            "OrcaParams.neighbor_dist",
            self.neighbor_dist,
            f"a number > 0 and at most {MAX_NEIGHBOR_DIST:g} m, or inf (every agent)",
            lambda d: d > 0 and (d <= MAX_NEIGHBOR_DIST or d == math.inf),
        )
        object.__setattr__(self, "neighbor_dist", dist)
        expected = f"an int in [0, {MAX_NEIGHBORS}]"
        count = whole_number("OrcaParams.max_neighbors", self.max_neighbors, expected, 0)
        if count > MAX_NEIGHBORS:
            raise SimulationError(f"OrcaParams.max_neighbors must be {expected}, got {count}")
        object.__setattr__(self, "max_neighbors", count)
        horizon = real_number(
            "OrcaParams.time_horizon",
            self.time_horizon,
            f"a number of at least {MIN_TIME_HORIZON:g} s",
            lambda t: t >= MIN_TIME_HORIZON,
        )
        object.__setattr__(self, "time_horizon", horizon)


def neighbor_dist_beyond(params: OrcaParams) -> str | None:
    """Why ``params.neighbor_dist`` is refused as a run starts, "must be at least 1e-06 m, got 5e-324", or
    None when it is at least ``LEAST_NEIGHBOR_DIST``."""
    if params.neighbor_dist >= LEAST_NEIGHBOR_DIST:
        return None
    return f"must be at least {LEAST_NEIGHBOR_DIST:g} m, got {params.neighbor_dist!r}"


def preferred_velocities(
    positions: np.ndarray, goals: np.ndarray, v_pref: float, stop_radius: float = 0.0
) -> np.ndarray:
    """CrowdNav's preferred velocity: ``v_pref`` towards the goal, the raw goal offset (m/s) within 1 m.
    (CrowdNav's ORCA policy prefers unit speed whatever the agent's v_pref; the two agree at WorldFacts'
    v_pref = 1 m/s, and here a faster or slower crowd is one setting.)

    Agents strictly within ``stop_radius`` of their goal have reached it and prefer to stand still.
    positions, goals: ``(A, 2)`` m. Returns ``(A, 2)`` m/s.
    """
    offset = goals - positions
    dist = np.linalg.norm(offset, axis=-1, keepdims=True)
    far = dist > 1.0
    pref = np.where(far, offset / np.where(far, dist, 1.0) * v_pref, offset)
    return np.where(dist < stop_radius, 0.0, pref)


def nearest_neighbors(
    positions: np.ndarray, agents: np.ndarray, params: OrcaParams, seen: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The neighbours of each agent in ``agents``, nearest first, as RVO2's k-d tree query returns them;
    only agents in ``seen`` (default: all) are anyone's neighbours.

    Returns ``(index (S, K), valid (S, K))`` with ``K = min(max_neighbors, A - 1)``; the valid entries of a
    row form a prefix. Distance ties keep the lower index first.
    """
    n_agents = len(positions)
    k = min(params.max_neighbors, n_agents - 1)
    if k <= 0:
        return np.zeros((len(agents), 0), dtype=int), np.zeros((len(agents), 0), dtype=bool)
    diff = positions[None, :, :] - positions[agents, None, :]
    dist_sq = np.einsum("sai,sai->sa", diff, diff)
    dist_sq[np.arange(len(agents)), agents] = np.inf  # an agent is not its own neighbour
    if seen is not None:
        unseen = np.ones(n_agents, dtype=bool)
        unseen[seen] = False
        dist_sq[:, unseen] = np.inf  # never below neighbor_dist squared, even an infinite one
    order = np.argsort(dist_sq, axis=1, kind="stable")[:, :k]
    valid = np.take_along_axis(dist_sq, order, axis=1) < params.neighbor_dist**2
    return order, valid


def orca_halfplanes(
    positions: np.ndarray,
    velocities: np.ndarray,
    radii: np.ndarray,
    agents: np.ndarray,
    params: OrcaParams,
    dt: float,
    seen: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ORCA lines of every agent in ``agents`` against its neighbours (among ``seen``, default all), in
    RVO2's order.

    positions, velocities: ``(A, 2)``; radii: ``(A,)`` m (the radius RVO2 is given). A line is a point and a
    unit direction; the permitted velocities lie on its left (``det(direction, point - v) <= 0``).
    Returns ``points (S, K, 2)``, ``directions (S, K, 2)`` and ``counts (S,)``: row ``s`` holds
    ``counts[s]`` valid lines, the rest is padding.
    """
    nbr, valid = nearest_neighbors(positions, agents, params, seen)
    # Component arrays (S, K): cheaper than (S, K, 2) stacks for the few agents of a crowd.
    px, py = positions[:, 0], positions[:, 1]
    vx, vy = velocities[:, 0], velocities[:, 1]
    vix, viy = vx[agents][:, None], vy[agents][:, None]
    rx = px[nbr] - px[agents][:, None]  # relative position, from the agent to its neighbour
    ry = py[nbr] - py[agents][:, None]
    ux = vix - vx[nbr]  # relative velocity
    uy = viy - vy[nbr]
    comb_r = radii[agents][:, None] + radii[nbr]
    comb_r_sq = comb_r * comb_r
    dist_sq = rx * rx + ry * ry
    inv_th = 1.0 / params.time_horizon

    with np.errstate(divide="ignore", invalid="ignore"):
        # No collision: w goes from the centre of the cut-off circle to the relative velocity.
        wx = ux - inv_th * rx
        wy = uy - inv_th * ry
        w_len_sq = wx * wx + wy * wy
        w_len = np.sqrt(w_len_sq)
        dot1 = wx * rx + wy * ry
        on_cutoff = (dot1 < 0.0) & (dot1 * dot1 > comb_r_sq * w_len_sq)
        # On the cut-off circle: direction (w_y, -w_x) / |w|, u = (R / tau_h - |w|) w / |w|.
        cut_scale = (comb_r * inv_th - w_len) / w_len
        cut_dx, cut_dy = wy / w_len, -wx / w_len

        # On a leg: the tangent from the agent to the neighbour's disc, on the side of w.
        leg = np.sqrt(np.maximum(dist_sq - comb_r_sq, 0.0))
        on_left = rx * wy - ry * wx > 0.0
        sign = np.where(on_left, 1.0, -1.0)
        leg_dx = (rx * leg - sign * ry * comb_r) / dist_sq
        leg_dy = (sign * rx * comb_r + ry * leg) / dist_sq
        leg_dx, leg_dy = sign * leg_dx, sign * leg_dy
        dot2 = ux * leg_dx + uy * leg_dy

        # Collision: the cut-off circle of one simulation time step, so the overlap is resolved in one step.
        cx = ux - rx / dt
        cy = uy - ry / dt
        c_len = np.sqrt(cx * cx + cy * cy)
        degenerate = c_len <= 0.0
        if degenerate.any():
            # The measure-zero 0/0 case (module docstring): the unit vector from the neighbour to the agent.
            apart_x, apart_y = _apart(rx, ry, dist_sq, agents, nbr)
            cx = np.where(degenerate, apart_x, cx)
            cy = np.where(degenerate, apart_y, cy)
            c_unit = np.where(degenerate, 1.0, c_len)
        else:
            c_unit = c_len
        col_scale = (comb_r / dt - c_len) / c_unit
        col_dx, col_dy = cy / c_unit, -cx / c_unit

        # np.where evaluates every branch: the branches not taken may hold the 0/0 above, hence the errstate.
        colliding = dist_sq <= comb_r_sq
        dir_x = np.where(colliding, col_dx, np.where(on_cutoff, cut_dx, leg_dx))
        dir_y = np.where(colliding, col_dy, np.where(on_cutoff, cut_dy, leg_dy))
        u_x = np.where(colliding, col_scale * cx, np.where(on_cutoff, cut_scale * wx, dot2 * leg_dx - ux))
        u_y = np.where(colliding, col_scale * cy, np.where(on_cutoff, cut_scale * wy, dot2 * leg_dy - uy))
    # Reciprocity: each agent takes half of the change that avoids the collision.
    points = np.stack([vix + 0.5 * u_x, viy + 0.5 * u_y], axis=-1)
    directions = np.stack([dir_x, dir_y], axis=-1)
    return points, directions, valid.sum(axis=1)


def _check_magnitudes(
    positions: np.ndarray, velocities: np.ndarray, pref: np.ndarray, radii: np.ndarray, speeds: np.ndarray
) -> None:
    """SimulationError (a ValueError) for a NaN, an infinity or a component beyond ``MOST_COORDINATE``.

    The sums of squares, five BLAS calls (a few microseconds, no floating-point warnings), settle every
    state the simulator makes: within ``MOST_COORDINATE**2`` every component is within the bound; NaN, inf
    or a larger sum go on to the exact test by component."""
    most = MOST_COORDINATE
    squares = np.vdot(positions, positions) + np.vdot(velocities, velocities) + np.vdot(pref, pref)
    if squares + np.vdot(radii, radii) + np.vdot(speeds, speeds) <= most * most:
        return  # every step's path: the names below are for a refusal only
    arrays = {
        "positions": (positions, "m"),
        "velocities": (velocities, "m/s"),
        "pref_velocities": (pref, "m/s"),
        "radii": (radii, "m"),  # a radius of 1e300 overflowed the combined radius' square
        "max_speeds": (speeds, "m/s"),
    }
    for name, (values, unit) in arrays.items():
        beyond = ~(np.abs(values) <= most)
        if beyond.any():
            raise SimulationError(
                f"orca_velocities: every {name} component must be finite and within ±{most:g} {unit}, got "
                f"{got(float(values[beyond][0]))}"
            )


def _apart(
    rx: np.ndarray, ry: np.ndarray, dist_sq: np.ndarray, agents: np.ndarray, nbr: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The unit vector from each neighbour to its agent, ``(S, K)`` components, for the 0/0 overlap.

    Two agents at the same point have no such vector; there the lower index goes +x and the higher -x, so the
    two directions of a pair are opposite (as -r / |r| is for distinct points) and the pair separates. One
    fixed direction for both would push them the same way, and they would never part.
    """
    r_len = np.sqrt(dist_sq)
    distinct = r_len > 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        apart_x = np.where(distinct, -rx / r_len, np.where(agents[:, None] < nbr, 1.0, -1.0))
        apart_y = np.where(distinct, -ry / r_len, 0.0)
    return apart_x, apart_y


def orca_velocities(
    positions: np.ndarray,
    velocities: np.ndarray,
    pref_velocities: np.ndarray,
    radii: np.ndarray | float,
    max_speeds: np.ndarray | float,
    params: OrcaParams,
    dt: float,
    agents: np.ndarray | None = None,
    seen: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """New velocities of ``agents`` (default: all) as one RVO2 ``doStep`` would compute them.

    positions, velocities: ``(A, 2)`` current state of every agent (each avoids all the others, or those in
    ``seen`` alone: a replayed person sees the robots, crowdsim.reaction);
    pref_velocities: ``(S, 2)`` for the agents in ``agents``; radii, max_speeds: scalars or ``(A,)``.
    dt: the simulation time step, a real number of seconds of at least ``crowdsim.world.MIN_DT`` (used only
    when agents already overlap).
    Returns ``(velocities (S, 2), used_lp3 (S,) bool)``. SimulationError (a ValueError) for a NaN, an infinity
    or a value beyond ``crowdsim.world.MOST_COORDINATE`` in positions, velocities, pref_velocities, radii or
    max_speeds, whose squares would overflow, and for a shorter dt, whose inverse would.
    """
    refuse_bools("orca_velocities", dt=dt, radii=radii, max_speeds=max_speeds)
    beyond = neighbor_dist_beyond(params)
    if beyond is not None:  # what a run's checks refuse, for whoever steps the crowd in Python
        raise SimulationError(f"orca_velocities: OrcaParams.neighbor_dist {beyond}")
    dt = seconds("orca_velocities: dt", dt)
    positions = np.asarray(positions, dtype=float)
    velocities = np.asarray(velocities, dtype=float)
    n_agents = len(positions)
    agents = np.arange(n_agents) if agents is None else np.asarray(agents, dtype=int)
    radii = np.broadcast_to(np.asarray(radii, dtype=float), (n_agents,))
    max_speeds = np.broadcast_to(np.asarray(max_speeds, dtype=float), (n_agents,))[agents]
    pref = np.asarray(pref_velocities, dtype=float).reshape(len(agents), 2)
    _check_magnitudes(positions, velocities, pref, radii, max_speeds)
    if not dt >= MIN_DT:  # NaN too
        raise SimulationError(f"orca_velocities: dt must be at least {MIN_DT:g} s, got {dt!r}")

    # The 2-D program's starting point: the preferred velocity, shortened onto the max-speed disc.
    speed = np.linalg.norm(pref, axis=1)
    too_fast = speed > max_speeds
    start = np.where(too_fast[:, None], pref * (max_speeds / np.where(too_fast, speed, 1.0))[:, None], pref)
    used_lp3 = np.zeros(len(agents), dtype=bool)
    if len(agents) == 0 or n_agents < 2:
        return start, used_lp3

    points, directions, counts = orca_halfplanes(positions, velocities, radii, agents, params, dt, seen)
    k = points.shape[1]
    slot_valid = np.arange(k)[None, :] < counts[:, None]
    off = points - start[:, None, :]
    violated = (directions[..., 0] * off[..., 1] - directions[..., 1] * off[..., 0] > 0.0) & slot_valid
    todo = np.flatnonzero(violated.any(axis=1))
    if len(todo) == 0:
        return start, used_lp3
    new = start.copy()
    # One conversion to nested Python lists (agent, xy, line) for all the agents that need the program.
    pts = points[todo].transpose(0, 2, 1).tolist()
    dirs = directions[todo].transpose(0, 2, 1).tolist()
    opts = pref[todo].tolist()
    speeds = max_speeds[todo].tolist()
    for row, s in enumerate(todo.tolist()):
        c = int(counts[s])
        px, py, dx, dy = pts[row][0][:c], pts[row][1][:c], dirs[row][0][:c], dirs[row][1][:c]
        fail, rx, ry = lp2(px, py, dx, dy, speeds[row], opts[row][0], opts[row][1], False)
        if fail < c:
            used_lp3[s] = True
            rx, ry = lp3(px, py, dx, dy, fail, speeds[row], rx, ry)
        new[s] = rx, ry
    return new, used_lp3
