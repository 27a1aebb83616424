"""A stalled robot and the teammate in its way move together (``MPCConfig.dmpc_pairs``), and so do robots
whose plans run into each other (``MPCConfig.dmpc_conflicts``): DMPC's way out of the equilibria that no
single robot can leave.

Why. With twelve robots and fixed goals (docs/examples/many_robots.toml), most failed DMPC episodes are lost
at the arrival, not in the crossing: the flock is half-way at 16.2 s in them against 14.0 s in the successes
(benchmarks/robot_scaling.py), then a robot waits short of its goal until the time limit. A late robot in
front of a parked teammate is a Nash equilibrium of Algorithm 2's game: its best response stops short of the
teammate, and the teammate's best response to a plan that stops short is to stay. Only a joint move (the
teammate aside, the late robot through) lowers the potential F, and CMPC's joint solve makes it.

The rule. After the step's IBR loop, each robot the stall watch marks (mpc/stall.py: no 0.25 m of progress
towards its goal over ``stall_release_s``, not arrived), in index order, solves the joint NLP (Eq. 17) over
its own and its blocker's controls (the active teammate nearest to the segment from it to its Eq. 8 target),
every other robot's plan fixed, from the current plans and under the humans predicted for them. The pair's new
plans are kept when they lower F by ``epsilon``, as Algorithm 2 keeps a best response that improves by
epsilon; the next pair starts from them. It is a block-coordinate step on the same potential whose
single-robot steps Algorithm 2 takes; the paper's DMPC (``dmpc_pairs = False``, the default) never runs it.

Measured with the paper's per-pair flocking weight: 12 robots 44 -> 56 % (fixed goals), 82 -> 88 % (slots).
With ``flocking_weight="per_robot"`` it adds nothing measurable at 5, 6 or 12 robots (mpc/dmpc.py).

Conflicts. The loop can end on plans that bring two robots within d_min of each other: under the paper's
Jacobi update each plan answers plans replaced meanwhile, and among people an epsilon-Nash point can plan a
squeezed pair into each other. After the stalled pairs, the robots of each such pair, joined where pairs
share a robot (four robots meeting in the middle of their circle: pair by pair each move ran into a third),
solve the same joint NLP from the plans and from braking (from colliding plans the first solve stayed where
it was), the better kept when F falls by epsilon, the group of the closest pair first. Robots trading places
(4 and 8, Jacobi): contact in 1 of 10 episodes each -> none, the closest 0.33 / 0.53 -> 1.10 / 0.91 m;
among people with the safe configuration, 4 and 6 robots, 100 episodes each: touches 4 -> 0 of 200
(docs/results.md, "DMPC conflict moves").
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from mpc.cmpc import IBRResult
from mpc.dmpc_keep import accept
from mpc.dynamics import braking, rollout_numpy
from mpc.nlp import JointNLP
from mpc.solvers import better
from mpc.step_data import StepData


def stalled(data: StepData) -> np.ndarray:
    """Indices of the active robots the stall watch holds out of flocking (``StepData.flocking`` False)."""
    if data.flocking is None:
        return np.zeros(0, dtype=int)
    arrived = np.zeros(data.n_robots, dtype=bool) if data.arrived is None else np.asarray(data.arrived, bool)
    held = ~np.asarray(data.flocking, dtype=bool) & np.asarray(data.active, dtype=bool) & ~arrived
    return np.flatnonzero(held)


def blocker(data: StepData, i: int) -> int | None:
    """The active teammate nearest to robot ``i``'s way: to the segment from its position to its Eq. 8 target
    (ties: the nearer to robot ``i``). None when ``i`` has no active teammate."""
    positions = data.states[:, :2]
    start, target = positions[i], data.reference_targets()[i]
    way = target - start
    length2 = float(way @ way)
    along = (
        np.clip((positions - start) @ way / length2, 0.0, 1.0) if length2 > 0 else np.zeros(len(positions))
    )
    off_way = np.linalg.norm(positions - (start + along[:, None] * way), axis=1)
    distances = off_way + 1e-6 * np.linalg.norm(positions - start, axis=1)
    distances[i] = np.inf
    distances[~np.asarray(data.active, dtype=bool)] = np.inf
    j = int(np.argmin(distances))
    return None if not np.isfinite(distances[j]) else j


def conflicts(data: StepData, positions: np.ndarray, d_min: float) -> list[tuple[int, int]]:
    """Pairs ``(i, j)``, ``i < j``, of active robots whose planned positions ``(M, H, 2)`` come closer than
    ``d_min`` at some step of the horizon, the closest first (ties in index order)."""
    active = np.asarray(data.active, dtype=bool)
    i, j, gaps = _closest(positions)
    near = np.flatnonzero((gaps < d_min) & active[i] & active[j])
    near = near[np.argsort(gaps[near], kind="stable")]
    return [(int(i[k]), int(j[k])) for k in near]


def _closest(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every pair ``i < j`` of the planned positions ``(K, H, 2)`` and how close it comes over the horizon."""
    i, j = np.triu_indices(len(positions), k=1)
    return i, j, np.linalg.norm(positions[i] - positions[j], axis=-1).min(axis=1)


def conflict_groups(data: StepData, positions: np.ndarray, d_min: float) -> list[tuple[int, ...]]:
    """The robots of ``conflicts``' pairs joined where they share a robot (three robots meeting in the middle
    of a circle are one group: pair by pair, each move ran into the third), each group sorted, the group of
    the closest pair first."""
    group = list(range(data.n_robots))  # union-find: each robot's representative

    def root(k: int) -> int:
        while group[k] != k:
            k = group[k]
        return k

    pairs = conflicts(data, positions, d_min)
    for i, j in pairs:
        group[root(j)] = root(i)
    groups: dict[int, list[int]] = {}
    for i, _ in pairs:  # closest first: the groups in the order of their closest pair
        groups.setdefault(root(i), [])
    for k in range(data.n_robots):
        if root(k) in groups and any(k in pair for pair in pairs):
            groups[root(k)].append(k)
    return [tuple(members) for members in groups.values()]


class _Moves(NamedTuple):
    """The plans as the pair moves leave them, and what the moves took."""

    accels: np.ndarray
    potential: float
    lam_x: np.ndarray | None
    lam_g: np.ndarray | None
    solves: int
    iterations: int
    kept: bool


def pair_moves(joint: JointNLP, data: StepData, result: IBRResult, until: float = math.inf) -> IBRResult:
    """``result`` after the pair moves (module docstring): of its stalled robots (``dmpc_pairs``), then of
    the groups whose plans, as those moves leave them, conflict (``dmpc_conflicts``); unchanged when nothing
    was solved, no group asks for a move or none lowers F by epsilon. No move starts after ``until``
    (``time.perf_counter()``: the step's time limit, as the IBR loop's)."""
    cfg = joint.cfg
    # prediction is None exactly when nothing was solved (IBRResult.solved)
    if result.prediction is None or not np.isfinite(result.potential):
        return result
    moves = _Moves(
        result.accels,
        result.potential,
        result.lam_x,
        result.lam_g,
        result.solves,
        result.solver_iterations,
        False,
    )
    if cfg.dmpc_pairs:
        held = [(int(i), j) for i in stalled(data) if (j := blocker(data, int(i))) is not None]
        moves = _move(joint, data, result.prediction, held, moves, until, restart=False)
    if cfg.dmpc_conflicts:
        planned = rollout_numpy(data.states, moves.accels, cfg.dt)[0]
        groups = conflict_groups(data, planned, cfg.d_min)
        moves = _move(joint, data, result.prediction, groups, moves, until, restart=True)
    if not moves.kept:
        return dataclasses.replace(result, solves=moves.solves, solver_iterations=moves.iterations)
    return dataclasses.replace(
        result,
        accels=moves.accels,
        positions=rollout_numpy(data.states, moves.accels, cfg.dt)[0],
        potential=moves.potential,
        potentials=(*result.potentials, moves.potential),
        solves=moves.solves,
        solver_iterations=moves.iterations,
        lam_x=moves.lam_x,
        lam_g=moves.lam_g,
    )


def _move(
    joint: JointNLP,
    data: StepData,
    prediction: np.ndarray,
    pairs: Sequence[tuple[int, ...]],
    moves: _Moves,
    until: float,
    *,
    restart: bool,
) -> _Moves:
    """Each group (a pair, or more) in turn solves the joint NLP over its plans, the others' fixed, from the
    plans the moves before it left (and, with ``restart``, again from the group braking, the better kept:
    from the plans that collide the solve stayed in their local minimum); kept when F drops by epsilon. With
    ``restart`` (the conflicts) a group an earlier move set apart is passed over."""
    cfg = joint.cfg
    accels, potential, lam_x, lam_g, solves, iterations, kept = moves
    brake = braking(data.states, cfg.horizon, cfg.dt, cfg.a_max) if restart and pairs else None
    for members in pairs:
        if time.perf_counter() > until:
            break
        chosen = list(members)
        if brake is not None and kept:  # still in conflict, after the moves before it?
            planned = rollout_numpy(data.states[chosen], accels[chosen], cfg.dt)[0]
            if _closest(planned)[2].min() >= cfg.d_min:
                continue
        free = np.zeros(data.n_robots, dtype=bool)
        free[chosen] = True
        sol = joint.solve_group(data, prediction, accels, free)
        solves, iterations = solves + 1, iterations + sol.iterations
        if brake is not None:
            start = accels.copy()
            start[free] = brake[free]
            other = joint.solve_group(data, prediction, start, free)
            solves, iterations = solves + 1, iterations + other.iterations
            sol = better(sol, other)
        # The joint NLP's objective is F itself (as CMPC reads it): sol.cost is F of the pair's new plans.
        if sol.success and accept(sol.cost, potential, cfg.epsilon):
            accels, potential, kept = sol.accels, sol.cost, True
            if lam_x is not None and lam_g is not None:
                lam_x, lam_g = lam_x.copy(), lam_g.copy()
                lam_x[free] = sol.lam_x.reshape(lam_x.shape)[free]
                lam_g[free] = sol.lam_g.reshape(lam_g.shape)[free]
    return _Moves(accels, potential, lam_x, lam_g, solves, iterations, kept)
