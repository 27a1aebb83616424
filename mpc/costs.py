"""Every cost term of the paper, written once on CasADi matrices (SX, MX or DM alike).

The joint NLP (Eq. 17), the local NLPs (Eq. 5), the coupled NLP and the numeric checks of CMPC/DMPC all
call these functions, so the formulations cannot drift apart. Numbers go in as ``casadi.DM`` (or through a
``casadi.Function`` built from these expressions) and come out as DM.

Layout (see mpc/dynamics.py): a robot's positions, velocities and controls over the horizon are ``(2, H)``
matrices, column ``k`` at ``t+k+1`` (controls at ``t+k``). The humans' predicted positions are one
``(2, H * N_h)`` matrix, column ``k * N_h + n`` for human ``n`` at ``t+k+1``: the column-major reshape of a
row-major ``(H, N_h, 2)`` array, which is how predictions travel as NLP parameters.

Potential (Eq. 16). The paper writes the shared part as a sum over ``i, j in R, i != j``. For Lemma 1
(``dC_i/du_i = dF/du_i``) each unordered pair must be counted once: with symmetric ``J_ij = J_ji`` an ordered
double sum gives ``dF/du_i = dJ_i/du_i + 2 sum_j dJ_ij/du_i``. ``potential`` therefore sums over ``i < j``,
which is the potential of Liu et al. (2023, Theorem 8) that the paper's proof refers to; a test checks the
lemma numerically.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca

from mpc.config import MPCConfig
from mpc.dynamics import Symbolic, rollout

# Keeps the direction of Eq. 8 defined when a robot stands exactly on its goal (the step is then 0 anyway).
_TINY = 1e-12


def smooth_norm(z: Symbolic, delta: float) -> Symbolic:
    """``sqrt(z^T z + delta)`` column by column: the everywhere-differentiable norm of Section IV."""
    return ca.sqrt(ca.sum1(z**2) + delta)


def smax(z: Symbolic, mu: float) -> Symbolic:
    """Smoothed max(z, 0) of Section IV, ``log(exp(mu z) + 1) / mu``, elementwise.

    Evaluated as ``max(z, 0) + log1p(exp(-mu |z|)) / mu``: the same function, but ``exp`` never overflows when
    an IPOPT iterate (which may violate the linear velocity constraints) makes ``mu z`` large.
    """
    return ca.fmax(z, 0) + ca.log1p(ca.exp(-mu * ca.fabs(z))) / mu


def reference_trajectory(
    position: Symbolic, goal: Symbolic, horizon: int, dt: float, v_max: float
) -> Symbolic:
    """Eq. 8: ``(2, H)`` points on the straight line from the current position to the goal.

    Each step advances ``min(dt v_max, remaining distance)`` along the fixed direction from ``s_t`` to the
    goal, so the reference moves at ``v_max`` and stops on the goal. A function of parameters only (no
    derivative with respect to the controls is ever taken through it).
    """
    offset = goal - position
    direction = offset / ca.fmax(ca.norm_2(offset), _TINY)
    ref = position
    points = []
    for _ in range(horizon):
        ref = ref + ca.fmin(dt * v_max, ca.norm_2(goal - ref)) * direction
        points.append(ref)
    return ca.horzcat(*points)


def goal_cost(
    positions: Symbolic, reference: Symbolic, position: Symbolic, goal: Symbolic, delta: Symbolic | float
):
    """Eq. 7: squared tracking error to the reference, divided by ``||s_t - s_goal|| + delta``."""
    return ca.sum2(ca.sum1((positions - reference) ** 2)) / (ca.norm_2(position - goal) + delta)


def acceleration_cost(accels: Symbolic) -> Symbolic:
    """Eq. 9: ``sum_k a_k^T a_k``."""
    return ca.sum2(ca.sum1(accels**2))


def jerk_cost(accels: Symbolic, last_action: Symbolic) -> Symbolic:
    """Eq. 10: ``sum_k (a_k - a_{k-1})^T (a_k - a_{k-1})`` with ``a_{t-1}`` the action applied last."""
    previous = ca.horzcat(last_action, accels[:, :-1])
    return ca.sum2(ca.sum1((accels - previous) ** 2))


def human_collision_cost(
    positions: Symbolic,
    velocities: Symbolic,
    humans: Symbolic,
    n_humans: int,
    cfg: MPCConfig,
    margins: Symbolic | None = None,
) -> Symbolic:
    """Eq. 11 through the penalty of Section IV, summed over humans and steps. Unweighted.

    ``sum_j sum_k smax((d_min + m_jk)^2 + rho ||v_{k+1}||^2 - ||s_{k+1} - s_j,k+1||^2)``; ``humans`` is
    ``(2, H * N_h)`` (module docstring). ``margins``: ``m_jk`` as a ``(1, H * N_h)`` row in the columns of
    ``humans`` (the NLPs pass a parameter: a margin per human and step); None: ``m_k = cfg.human_margin(k)``
    for every human. All 0 is the paper's method.
    """
    total = positions[0, 0] * 0  # the type of the inputs (SX, MX or DM), also with no humans
    for k in range(positions.shape[1]):
        columns = slice(k * n_humans, (k + 1) * n_humans)
        block = humans[:, columns]
        dist2 = ca.sum1((block - ca.repmat(positions[:, k], 1, n_humans)) ** 2)
        margin = cfg.human_margin(k) if margins is None else margins[:, columns]
        g = (cfg.d_min + margin) ** 2 + cfg.rho * ca.sumsqr(velocities[:, k]) - dist2
        total = total + ca.sum2(smax(g, cfg.mu))
    return total


def robot_collision_cost(positions_i: Symbolic, positions_j: Symbolic, cfg: MPCConfig) -> Symbolic:
    """Eq. 12 through the penalty of Section IV: ``sum_k smax(d_min^2 - ||s_i,k+1 - s_j,k+1||^2)``."""
    g = cfg.d_min**2 - ca.sum1((positions_i - positions_j) ** 2)
    return ca.sum2(smax(g, cfg.mu))


def flocking_cost(
    positions_i: Symbolic, positions_j: Symbolic, cfg: MPCConfig, d_ij: Symbolic | float | None = None
) -> Symbolic:
    """Eq. 15: ``sum_k (||s_i,k+1 - s_j,k+1|| - d_ij)^2`` with the smoothed norm. Unweighted. ``d_ij``: the
    pair's distance (``MPCConfig.flock_distance``; a parameter in the NLPs), None: ``cfg.d_flock``."""
    d = cfg.d_flock if d_ij is None else d_ij
    return ca.sum2((smooth_norm(positions_i - positions_j, cfg.delta) - d) ** 2)


@dataclass(frozen=True)
class Track:
    """One robot over the horizon: the given start and its (symbolic or numeric) plan."""

    state: Symbolic  # (4, 1) [s_x, s_y, v_x, v_y] at t
    accels: Symbolic  # (2, H) controls at t..t+H-1
    last_action: Symbolic  # (2, 1) control applied at t-1 (Eq. 10)
    goal: Symbolic  # (2, 1)
    positions: Symbolic  # (2, H) at t+1..t+H
    velocities: Symbolic  # (2, H)
    target: Symbolic  # (2, 1) where Eq. 8's reference heads: the goal, or a detour point (mpc/guidance.py)
    # m added to delta in Eq. 7's weight 1 / (||s_t - s_goal|| + delta): 0 is the paper's; on_goal="yield"
    # softens a robot parked on its goal so that a teammate can push it aside (mpc/config.py)
    goal_slack: Symbolic | float = 0.0


def make_track(
    state: Symbolic,
    accels: Symbolic,
    last_action: Symbolic,
    goal: Symbolic,
    dt: float,
    target: Symbolic | None = None,
    goal_slack: Symbolic | float = 0.0,
) -> Track:
    """A robot's track: Eq. 2 rolled out from ``state`` under ``accels``; ``target`` defaults to the goal."""
    positions, velocities = rollout(state, accels, dt)
    target = goal if target is None else target
    return Track(state, accels, last_action, goal, positions, velocities, target, goal_slack)


def individual_cost(
    track: Track, humans: Symbolic, n_humans: int, cfg: MPCConfig, margins: Symbolic | None = None
) -> Symbolic:
    """Eq. 13: ``J_i = w_goal J_goal + w_acce J_acce + w_jerk J_jerk + w_coll sum_j J_coll_ij``.

    Eq. 8's reference heads for ``track.target`` (the goal unless guidance detours it); Eq. 7's weight
    ``1 / (||s_t - s_goal|| + delta)`` keeps the real goal."""
    position = track.state[0:2]
    reference = reference_trajectory(position, track.target, track.accels.shape[1], cfg.dt, cfg.v_max)
    return (
        cfg.w_goal * goal_cost(track.positions, reference, position, track.goal, cfg.delta + track.goal_slack)
        + cfg.w_acce * acceleration_cost(track.accels)
        + cfg.w_jerk * jerk_cost(track.accels, track.last_action)
        + cfg.w_coll * human_collision_cost(track.positions, track.velocities, humans, n_humans, cfg, margins)
    )


def shared_cost(
    positions_i: Symbolic,
    positions_j: Symbolic,
    w_floc: Symbolic,
    cfg: MPCConfig,
    d_ij: Symbolic | float | None = None,
) -> Symbolic:
    """Eq. 14: ``J_ij = w_coll J_coll_ij + w_floc_ij J_floc_ij``; symmetric in ``i, j`` (Lemma 1).

    ``w_floc`` is per pair (a parameter in the NLPs) so that a robot on its goal stops pulling the others
    while the weights stay symmetric; so is ``d_ij`` (``flocking_cost``), symmetric too.
    """
    return cfg.w_coll * robot_collision_cost(positions_i, positions_j, cfg) + w_floc * flocking_cost(
        positions_i, positions_j, cfg, d_ij
    )


def pair_index(i: int, j: int, n_robots: int) -> int:
    """Index of the unordered pair ``{i, j}`` in the row-major list ``(0,1), (0,2), .., (M-2, M-1)``."""
    a, b = (i, j) if i < j else (j, i)
    return a * n_robots - a * (a + 1) // 2 + (b - a - 1)


def robot_cost(
    track: Track,
    other_positions: Sequence[Symbolic],
    other_floc_weights: Sequence[Symbolic],
    humans: Symbolic,
    n_humans: int,
    cfg: MPCConfig,
    margins: Symbolic | None = None,
    other_distances: Sequence[Symbolic] | None = None,
) -> Symbolic:
    """``C_i = J_i + sum_{j != i} J_ij`` (Definition 1, the objective of Eq. 5), others' positions given;
    ``margins``: see :func:`human_collision_cost`; ``other_distances``: each pair's d_ij (None: d_flock)."""
    total = individual_cost(track, humans, n_humans, cfg, margins)
    distances = [None] * len(other_positions) if other_distances is None else other_distances
    for positions_j, w, d in zip(other_positions, other_floc_weights, distances, strict=True):
        total = total + shared_cost(track.positions, positions_j, w, cfg, d)
    return total


def potential(
    tracks: Sequence[Track],
    floc_weights: Symbolic,
    humans: Symbolic,
    n_humans: int,
    cfg: MPCConfig,
    margins: Symbolic | None = None,
    distances: Symbolic | None = None,
) -> Symbolic:
    """Eq. 16 with each unordered pair once (module docstring): ``F = sum_i J_i + sum_{i<j} J_ij``.

    ``floc_weights`` holds one weight per unordered pair in :func:`pair_index` order, ``distances`` (None:
    d_flock for every pair) one d_ij.
    """
    n_robots = len(tracks)
    total = 0
    for i, track in enumerate(tracks):
        total = total + individual_cost(track, humans, n_humans, cfg, margins)
        for j in range(i + 1, n_robots):
            k = pair_index(i, j, n_robots)
            d = None if distances is None else distances[k]
            total = total + shared_cost(track.positions, tracks[j].positions, floc_weights[k], cfg, d)
    return total


def collision_penalty(
    tracks: Sequence[Track], humans: Symbolic, n_humans: int, cfg: MPCConfig, margins: Symbolic | None = None
) -> Symbolic:
    """The collision part of the potential: ``w_coll`` times every robot-human and robot-robot penalty."""
    total = 0
    for i, track in enumerate(tracks):
        total = total + human_collision_cost(
            track.positions, track.velocities, humans, n_humans, cfg, margins
        )
        for other in tracks[i + 1 :]:
            total = total + robot_collision_cost(track.positions, other.positions, cfg)
    return dense(cfg.w_coll * total)


def dense(expr: Symbolic) -> Symbolic:
    """``expr`` with its structural zeros made explicit; a dense ``expr`` comes back as the same object.

    A sum over no terms (one robot and no humans: no pair, no human) is a structurally empty 1x1, which
    mpc/fastcall.py cannot bind to an output buffer. Only that case changes: every other expression, and so
    every number of the normal case, is left untouched (a plain number too: no robots at all).
    """
    if not isinstance(expr, ca.SX | ca.MX | ca.DM) or expr.sparsity().is_dense():
        return expr
    return ca.densify(expr)
