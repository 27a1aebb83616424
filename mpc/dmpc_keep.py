"""Algorithm 2's lines 5-6 and their repairs: which of the robots' best responses a DMPC iteration keeps.

``PlanKeeper`` is mpc/dmpc.py's bookkeeping of accepted plans (its module docstring has the update rules and
their measurements): a plan is kept only if it lowers the robot's own cost C_i by at least epsilon
(``accept``), and a kept plan's multipliers warm-start that robot's next solve.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from mpc.config import MPCConfig
from mpc.dynamics import rollout_numpy
from mpc.local_params import LocalParams
from mpc.nlp import LocalNLP
from mpc.solvers import Solution


def accept(new_cost: float, old_cost: float, epsilon: float) -> bool:
    """Algorithm 2, lines 5-6: a new plan replaces the old one only if it lowers C_i by at least epsilon."""
    return new_cost <= old_cost - epsilon


class PlanKeeper:
    """The acceptance rules of one DMPC (``cfg.dmpc_update``), on its local NLP's cost function."""

    def __init__(self, cfg: MPCConfig, local: LocalNLP, n_robots: int):
        self.cfg, self.local, self.n_robots = cfg, local, n_robots

    def improvements(
        self,
        moving: np.ndarray,
        params: dict,
        accels: np.ndarray,
        sols: list[Solution],
        lam_x: np.ndarray | None,
        lam_g: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, str]:
        """Lines 5-6: keep a new plan only if it lowers C_i(., u_-i^(j-1)) by at least epsilon; a kept plan's
        multipliers warm-start the robot's next solve. Returns the plans, the multipliers (``lam_x`` and
        ``lam_g`` updated in place, or made on the first kept plan) and the first failed solve's status."""
        old_costs = self.local.costs([accels[i] for i in moving], [params[i] for i in moving])
        return self._keep(moving, accels, sols, old_costs, lam_x, lam_g)

    def _keep(
        self,
        moving: np.ndarray,
        accels: np.ndarray,
        sols: list[Solution],
        old_costs: np.ndarray,
        lam_x: np.ndarray | None,
        lam_g: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, str]:
        """Robot ``moving[k]`` keeps ``sols[k]`` if its cost ``sol.cost`` is at least epsilon below
        ``old_costs[k]``, the cost of its plan of iteration j-1 (both against the others' plans of j-1)."""
        new_accels = accels.copy()
        first_failure = ""
        for i, sol, old_cost in zip(moving, sols, old_costs, strict=True):
            if not sol.success:
                # A robot whose local solve failed keeps its plan, as if it had not improved; the step
                # fails only when no local solve ever succeeded (solve).
                first_failure = first_failure or sol.status
                continue
            # The local objective at the solution is C_i(u_i^(j), u_-i^(j-1)).
            if accept(sol.cost, old_cost, self.cfg.epsilon):
                new_accels[i] = sol.accels
                lam_x, lam_g = self._multipliers(i, sol, lam_x, lam_g)
        return new_accels, lam_x, lam_g, first_failure

    def relaxed(
        self,
        moving: np.ndarray,
        params: dict,
        accels: np.ndarray,
        sols: list[Solution],
        lam_x: np.ndarray | None,
        lam_g: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, str]:
        """Lines 5-6 for a relaxed step: the candidate plan is ``u_i^(j-1) + alpha (u_i* - u_i^(j-1))``
        (``alpha = cfg.dmpc_relaxation``; feasible, as a convex combination of two feasible plans), kept if
        it lowers C_i(., u_-i^(j-1)) by at least epsilon. Same returns as ``improvements``."""
        cfg = self.cfg
        alpha = cfg.dmpc_relaxation
        candidates = [
            accels[i] + alpha * (sol.accels - accels[i]) for i, sol in zip(moving, sols, strict=True)
        ]
        checks = self.local.costs(
            candidates + [accels[i] for i in moving], [params[i] for i in moving] * 2
        ).reshape(2, len(moving))
        relaxed = [
            replace(sol, accels=candidate, cost=float(cost))
            for sol, candidate, cost in zip(sols, candidates, checks[0], strict=True)
        ]
        return self._keep(moving, accels, relaxed, checks[1], lam_x, lam_g)

    def in_turn(
        self,
        step: LocalParams,
        moving: np.ndarray,
        params: dict,
        prediction: np.ndarray,
        accels: np.ndarray,
        sols: list[Solution],
        lam_x: np.ndarray | None,
        lam_g: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, str]:
        """Lines 5-6 one robot at a time: the best responses (all computed against u^(j-1)) are taken in
        order of their improvement of C_i(., u_-i^(j-1)), largest first, and each is kept only if it lowers
        C_i by at least epsilon against the plans kept so far. In an exact potential game a kept plan lowers
        F by as much as it lowers C_i, so F falls by at least epsilon per kept plan and the loop cannot
        cycle. Same returns as ``improvements``."""
        cfg = self.cfg
        old_costs = self.local.costs([accels[i] for i in moving], [params[i] for i in moving])
        gains = [
            old - sol.cost if sol.success else -math.inf for sol, old in zip(sols, old_costs, strict=True)
        ]
        order = sorted(range(len(moving)), key=lambda k: -gains[k])  # stable: ties in robot order
        new_accels, positions = accels.copy(), None
        failure = ""
        for k in order:
            i, sol = moving[k], sols[k]
            if not sol.success:
                failure = failure or sol.status
                continue
            if positions is None:  # nothing kept yet: the others' plans are u_-i^(j-1)
                new_cost, old_cost = sol.cost, old_costs[k]
            else:
                q = step.row(i, positions, prediction)
                new_cost, old_cost = self.local.costs([sol.accels, new_accels[i]], [q, q])
            if accept(new_cost, old_cost, cfg.epsilon):
                new_accels[i] = sol.accels
                positions = rollout_numpy(step.data.states, new_accels, cfg.dt)[0]
                lam_x, lam_g = self._multipliers(i, sol, lam_x, lam_g)
        return new_accels, lam_x, lam_g, failure

    def _multipliers(
        self, i: int, sol: Solution, lam_x: np.ndarray | None, lam_g: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``lam_x``, ``lam_g`` (made on the first kept plan) with robot ``i``'s row set from ``sol``."""
        h = self.cfg.horizon
        if lam_x is None or lam_g is None:
            lam_x = np.zeros((self.n_robots, h, 2))
            lam_g = np.zeros((self.n_robots, h, 2))
        lam_x[i] = sol.lam_x.reshape(h, 2)
        lam_g[i] = sol.lam_g.reshape(h, 2)
        return lam_x, lam_g
