"""A stalled robot and the teammate in its way move together (``MPCConfig.dmpc_pairs``): DMPC's way out of the
equilibria that no single robot can leave.

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
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mpc.cmpc import IBRResult
from mpc.dmpc_keep import accept
from mpc.dynamics import rollout_numpy
from mpc.nlp import JointNLP
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


def pair_moves(joint: JointNLP, data: StepData, result: IBRResult) -> IBRResult:
    """``result`` after the pair moves of its stalled robots (module docstring); unchanged when nothing was
    solved, nobody is stalled or no pair lowers F by epsilon."""
    cfg = joint.cfg
    held = stalled(data)
    # prediction is None exactly when nothing was solved (IBRResult.solved)
    if result.prediction is None or held.size == 0 or not np.isfinite(result.potential):
        return result
    accels, potential = result.accels, result.potential
    lam_x, lam_g = result.lam_x, result.lam_g
    solves, iterations, kept = result.solves, result.solver_iterations, False
    for i in held:
        j = blocker(data, int(i))
        if j is None:
            continue
        free = np.zeros(data.n_robots, dtype=bool)
        free[[i, j]] = True
        sol = joint.solve_group(data, result.prediction, accels, free)
        solves, iterations = solves + 1, iterations + sol.iterations
        # The joint NLP's objective is F itself (as CMPC reads it): sol.cost is F of the pair's new plans.
        if sol.success and accept(sol.cost, potential, cfg.epsilon):
            accels, potential, kept = sol.accels, sol.cost, True
            if lam_x is not None and lam_g is not None:
                lam_x, lam_g = lam_x.copy(), lam_g.copy()
                lam_x[free] = sol.lam_x.reshape(lam_x.shape)[free]
                lam_g[free] = sol.lam_g.reshape(lam_g.shape)[free]
    if not kept:
        return dataclasses.replace(result, solves=solves, solver_iterations=iterations)
    return dataclasses.replace(
        result,
        accels=accels,
        positions=rollout_numpy(data.states, accels, cfg.dt)[0],
        potential=potential,
        potentials=(*result.potentials, potential),
        solves=solves,
        solver_iterations=iterations,
        lam_x=lam_x,
        lam_g=lam_g,
    )
