"""Algorithm 2, IBR-based distributed MPC with the epsilon-Nash stopping rule.

At iteration ``j``: predict the humans given the robots' plans of iteration ``j-1``; every robot ``i`` solves
its local NLP (Eq. 5) given the others' plans ``x_-i^(j-1)``; it keeps the new plan only if
``C_i(u_i^(j), u_-i^(j-1)) <= C_i(u_i^(j-1), u_-i^(j-1)) - epsilon`` (else ``u_i^(j) = u_i^(j-1)``); the loop
ends when every robot satisfies ``C_i(u_i^(j), u_-i^(j)) <= C_i(u_i^(j-1), u_-i^(j)) + epsilon`` or at
``j_max``. A robot whose controls are pinned (``on_goal="brake"``) does not play: its plan is braking. A
failed local solve counts as a rejected plan.

Parallelism. The local solves of one iteration are independent. CasADi 3.8 releases the GIL while a solver
runs, so ``dmpc_parallel="threads"`` really runs them concurrently, each robot on its own solver instance (one
instance shared by threads segfaults). Whether that pays depends on free cores. benchmarks/control_step.py
--dmpc-parallel, 3 robots, 7 humans, closed loop on this 2-core machine: median step 32.7 ms serial vs
23.6 ms threads with the machine otherwise idle (load 1.0), but 33.7 ms vs 50.2 ms with the other engineers'
jobs running (load 3.5-4.4): warm local solves took 1-2 ms (IPOPT; Fatrop's take 0.5-1 ms), so waiting
for a core costs as much as the work.
``"serial"`` is the default because DMPC's long runs are sweeps, whose process workers already occupy every
core; ``"threads"`` is the faster choice for a single run on a machine with a free core.
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from mpc.cmpc import IBRResult, PredictFn, finite_prediction
from mpc.config import MPCConfig
from mpc.dynamics import braking, rollout_numpy
from mpc.fallback import Start
from mpc.nlp import JointNLP, LocalNLP, StepData
from mpc.solvers import Solution, better


def accept(new_cost: float, old_cost: float, epsilon: float) -> bool:
    """Algorithm 2, lines 5-6: a new plan replaces the old one only if it lowers C_i by at least epsilon."""
    return new_cost <= old_cost - epsilon


class DMPC:
    """Algorithm 2 for a fixed problem size; the local NLP (shared by all robots) is built once, here."""

    def __init__(self, cfg: MPCConfig, n_robots: int, n_humans: int):
        self.cfg, self.n_robots, self.n_humans = cfg, n_robots, n_humans
        self.local = LocalNLP(cfg, n_robots, n_humans)
        # Only to report F_t of the final plan, the common currency of CMPC and DMPC.
        self.joint = JointNLP(cfg, n_robots, n_humans)
        self._pool: ThreadPoolExecutor | None = None  # made on first use with dmpc_parallel="threads"

    def close(self) -> None:
        """Stop the solver threads; a later solve starts them again."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def _solve_all(
        self, jobs: list[tuple[int, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None, bool]]
    ):
        if self.cfg.dmpc_parallel != "threads":
            return [self.local.solve(*job) for job in jobs]
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=self.n_robots)
        return list(self._pool.map(lambda job: self.local.solve(*job), jobs))

    def _restart(
        self, data: StepData, moving: np.ndarray, params: dict, sols: list[Solution]
    ) -> tuple[list[Solution], list[Solution]]:
        """``multi_start``: robots whose first solution still pays collision penalty solve again from braking.

        Returns the better solution per robot (lower C_i) and the extra solutions.
        """
        cfg = self.cfg
        brake = braking(data.states, cfg.horizon, cfg.dt, cfg.a_max)
        penalties = self.local.penalties([s.accels for s in sols], [params[i] for i in moving])
        redo = [
            k
            for k, (sol, penalty) in enumerate(zip(sols, penalties, strict=True))
            if not sol.success or penalty > cfg.restart_penalty
        ]
        extra = self._solve_all(
            [(moving[k], params[moving[k]], brake[moving[k]], None, None, False) for k in redo]
        )
        out = list(sols)
        for k, other in zip(redo, extra, strict=True):
            out[k] = better(sols[k], other)
        return out, extra

    def solve(self, data: StepData, predict: PredictFn, start: Start) -> IBRResult:
        cfg, local = self.cfg, self.local
        t0 = time.perf_counter()
        pred_shape = (cfg.horizon, self.n_humans, 2)
        # Indices of the active robots; np.ndarray (as in _restart) so its items pass where an int is taken.
        moving: np.ndarray = np.flatnonzero(np.asarray(data.active, dtype=bool))
        accels = start.accels.copy()
        positions = rollout_numpy(data.states, accels, cfg.dt)[0]
        lam_x = None if start.lam_x is None else start.lam_x.copy()
        lam_g = None if start.lam_g is None else start.lam_g.copy()
        status, converged, first_failure = "ok", False, ""
        used, predictions, potentials = None, [], []
        solves = solver_iterations = iterations = 0
        for j in range(1, cfg.j_max + 1):
            iterations = j
            prediction = finite_prediction(predict(positions.transpose(1, 0, 2)), pred_shape)
            if prediction is None:
                status = "nan_prediction"
                break
            predictions.append(prediction)
            # Line 4: every robot's best response to the others' plans of iteration j-1.
            params = {i: local.params(i, data, positions, prediction) for i in moving}
            sols, n_solves, n_iterations = self._best_responses(
                data, moving, params, accels, lam_x, lam_g, start.first_solve(j)
            )
            solves += n_solves
            solver_iterations += n_iterations
            new_accels, lam_x, lam_g, failure = self._keep_improvements(
                moving, params, accels, sols, lam_x, lam_g
            )
            first_failure = first_failure or failure
            solved_now = any(s.success for s in sols)
            if solved_now:
                used = prediction
            # Lines 12-16: the epsilon-Nash check against the others' new plans. An iteration in which every
            # local solve failed proves nothing, so it cannot end the loop as converged.
            new_positions = rollout_numpy(data.states, new_accels, cfg.dt)[0]
            at_nash = self._at_nash(data, moving, accels, new_accels, new_positions, prediction)
            converged = solved_now and at_nash
            accels, positions = new_accels, new_positions
            if used is not None:
                potentials.append(self.joint.potential(accels, data, used))
            if converged:
                break
            if time.perf_counter() - t0 > cfg.time_limit_s:
                status = "timeout" if status == "ok" else status
                break
        if used is None and status == "ok" and first_failure:
            status = first_failure
        return IBRResult(
            accels=accels,
            positions=positions,
            prediction=used,
            potential=potentials[-1] if potentials else math.nan,
            iterations=iterations,
            solves=solves,
            # A solved step may keep u^(0) for every robot: rejecting non-improving plans is Algorithm 2.
            solved=used is not None,
            converged=converged,
            status=status,
            predictions=tuple(predictions),
            potentials=tuple(potentials),
            lam_x=lam_x,
            lam_g=lam_g,
            solver_iterations=solver_iterations,
        )

    def _best_responses(
        self,
        data: StepData,
        moving: np.ndarray,
        params: dict,
        accels: np.ndarray,
        lam_x: np.ndarray | None,
        lam_g: np.ndarray | None,
        flags: dict[str, bool],
    ) -> tuple[list[Solution], int, int]:
        """Line 4 for every moving robot, warm from its plan and multipliers of iteration j-1, then (when
        ``flags`` ask for it) ``_restart``. Returns the solutions, the solves and solver iterations spent."""
        jobs = [
            (
                i,
                params[i],
                accels[i],
                None if lam_x is None else lam_x[i],
                None if lam_g is None else lam_g[i],
                flags["explore"],
            )
            for i in moving
        ]
        sols: list[Solution] = self._solve_all(jobs)
        solves = len(sols)
        solver_iterations = sum(s.iterations for s in sols)
        if self.cfg.multi_start and flags["restart"]:
            sols, extra = self._restart(data, moving, params, sols)
            solves += len(extra)
            solver_iterations += sum(s.iterations for s in extra)
        return sols, solves, solver_iterations

    def _keep_improvements(
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
        cfg = self.cfg
        new_accels = accels.copy()
        first_failure = ""
        old_costs = self.local.costs([accels[i] for i in moving], [params[i] for i in moving])
        for i, sol, old_cost in zip(moving, sols, old_costs, strict=True):
            if not sol.success:
                # A robot whose local solve failed keeps its plan, as if it had not improved; the step
                # fails only when no local solve ever succeeded (solve).
                first_failure = first_failure or sol.status
                continue
            # The local objective at the solution is C_i(u_i^(j), u_-i^(j-1)).
            if accept(sol.cost, old_cost, cfg.epsilon):
                new_accels[i] = sol.accels
                if lam_x is None or lam_g is None:
                    lam_x = np.zeros((self.n_robots, cfg.horizon, 2))
                    lam_g = np.zeros((self.n_robots, cfg.horizon, 2))
                lam_x[i] = sol.lam_x.reshape(cfg.horizon, 2)
                lam_g[i] = sol.lam_g.reshape(cfg.horizon, 2)
        return new_accels, lam_x, lam_g, first_failure

    def _at_nash(
        self,
        data: StepData,
        moving: np.ndarray,
        accels: np.ndarray,
        new_accels: np.ndarray,
        new_positions: np.ndarray,
        prediction: np.ndarray,
    ) -> bool:
        """Lines 12-16: no robot's new plan is worse, by more than epsilon, than its old one against the
        others' new plans."""
        new_params = [self.local.params(i, data, new_positions, prediction) for i in moving]
        checks = self.local.costs(
            [new_accels[i] for i in moving] + [accels[i] for i in moving], new_params + new_params
        ).reshape(2, len(moving))
        return bool(np.all(checks[0] <= checks[1] + self.cfg.epsilon))
