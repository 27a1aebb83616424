"""Algorithm 2, IBR-based distributed MPC with the epsilon-Nash stopping rule, and two repairs of its update.

At iteration ``j``: predict the humans given the robots' plans of iteration ``j-1``; every robot ``i`` solves
its local NLP (Eq. 5) given the others' plans ``x_-i^(j-1)``; it keeps the new plan only if
``C_i(u_i^(j), u_-i^(j-1)) <= C_i(u_i^(j-1), u_-i^(j-1)) - epsilon`` (else ``u_i^(j) = u_i^(j-1)``); the loop
ends when every robot satisfies ``C_i(u_i^(j), u_-i^(j)) <= C_i(u_i^(j-1), u_-i^(j)) + epsilon`` or at
``j_max``. A robot whose controls are pinned (``on_goal="brake"``) does not play: its plan is braking. A
failed local solve counts as a rejected plan. That is ``dmpc_update="jacobi"``, ``dmpc_stop="regret"``, the
default.

Why the paper's update cycles. Every robot best-responds to the others' *old* plans at once (a Jacobi
update). Where robots stand close, each dodges the others' old plans and the new plans collide with each
other; the next iteration undoes it. Measured on ``CrowdEnv().reset(0, "circle", 7, 6)`` (6 robots, 7 humans,
constant velocity, 40 steps): every step ran to j_max = 10; all 6 robots kept a new plan in every iteration;
the epsilon-Nash test failed by more than 1e3 (a robot-robot penalty, w_coll = 1e7) in every iteration; F^(j)
of a step alternated 4.65e6, 6.36e6, 4.44e6, 6.09e6, ...: a period-2 cycle between colliding plans. With 3
robots from rest in a 1 m row it already alternates 2.1e7, 47, 1.7e7, 42, ... (tests/mpc/
test_dmpc_convergence.py); on the circle at M = 3 35 % of the steps run to j_max, 86 % of iterations failing
the test by more than epsilon.

The repairs (``dmpc_update``). The game is an exact potential game (Lemma 1): changing one robot's plan
changes F (Eq. 16) by exactly the change of that robot's C_i. So a plan kept because it lowers C_i by epsilon
*against the plans in force when it is kept* lowers F by epsilon, and an update built from such steps cannot
cycle.

* ``"gauss_seidel"``: the robots solve one after the other (index order), each against the latest plans
  (those kept earlier in the sweep), and keep or reject at once. Sequential: nothing to run in parallel.
* ``"sequential_accept"``: the M solves of Algorithm 2 (in parallel, against u^(j-1)); then the coordinator
  keeps the best responses one at a time, largest improvement first, each re-checked against the plans kept
  before it. The first robot's test is Algorithm 2's own; a later robot whose response no longer improves
  keeps its plan and solves again next iteration.
* ``"relaxed"``: Jacobi, each robot moving ``dmpc_relaxation`` (alpha) of the way to its best response, kept
  if that lowers C_i(., u_-i^(j-1)) by epsilon. No guarantee, and measured worse: half a best response can
  collide where neither end does (from rest, robots then do not move at all; F - F* below).

The stop (``dmpc_stop``). ``"regret"`` is lines 12-16. After a Gauss-Seidel sweep it nearly always holds at
once (a new plan rarely loses to the shifted old one): one sweep a step, robots far from an equilibrium.
``"no_improvement"`` ends at an iteration in which no robot keeps a new plan: no best response to the current
plans improves by epsilon, which is the paper's definition of an epsilon-Nash equilibrium itself rather than a
proxy for it. With epsilon = 1e-3 on costs of 10-1000 the improvements creep on for many iterations, so most
steps still reach j_max, but with F falling at every one of them.

Measured on recorded CMPC steps (7 humans, constant velocity; F* = CMPC's joint optimum of the same step):
F - F* median / p90 / max, and IBR iterations per step:

    M = 3 (40 steps)                    median     p90      max   its        M = 6 (30 steps)
    jacobi, regret                       0.117    10.3     71.4   4.67       12.9   3466    39016   8.40
    gauss_seidel, regret                 0.212     5.8     55.5   1.12       27.0   1599    62699   1.33
    gauss_seidel, no_improvement         0.004    0.06     29.7   6.08        1.2   10.1     35.2   9.07
    sequential_accept, no_improvement    0.007    0.33     29.7   7.70        2.8   21.9     60.6   9.20
    relaxed (0.5), regret                3.6     14655    2.1e6   1.07        746   4.3e5   2.6e6   1.40

and in closed loop, benchmarks/dmpc_scaling.py (3 circle episodes, 7 humans): at M = 6 jacobi succeeds in
1 of 3 episodes (99 % of steps at j_max, median step 143 ms), gauss_seidel + regret in 0 of 3 (11 ms),
gauss_seidel + no_improvement in 3 of 3 (43 ms), sequential_accept + no_improvement in 3 of 3 (44 ms serial,
34 ms threads). At M = 3 every rule succeeds in 3 of 3, and the repairs with no_improvement take more
iterations than jacobi (5.6 and 6.5 a step against 4.4): the default stays the paper's.

The start (``dmpc_start``): Algorithm 2 leaves u^(0) open; the shifted previous plan, else braking, or with
"heading" every robot heading for its target where that lowers F: mpc/dmpc_start.py, with its measurements.

The order of a Gauss-Seidel round (``dmpc_order``): robot index, or nearest to its target first (a parked
robot answers the late ones' plans before they answer its own). With the heading start and
many_robots.toml's settings, 50 episodes a row (benchmarks/robot_scaling.py --mpc dmpc_order=nearest_first):
12 robots 44 -> 50 % (fixed goals), 82 -> 92 % (slots); 3, 5, 6 robots 566 -> 562 successes of 600, and 2
of 50 episodes within 0.8 m of a human in most rows where index order had 0-1. Not in many_robots.toml.

Pair moves (``dmpc_pairs``, mpc/dmpc_pairs.py): after the loop, a stalled robot and the teammate in its way
solve the joint NLP over their two plans, kept when F falls by epsilon; the equilibrium of a late robot in
front of a parked teammate, which no best response leaves, falls to it. 12 robots 44 -> 56 % (fixed goals),
82 -> 88 % (slots); 3, 5, 6 robots 566 -> 568 successes of 600 (50 episodes a row), with per-pair
flocking. With per-robot flocking they add nothing (12 robots 92 % either way on fixed goals, 94 % without
against 90 % with on slots, at 1.7x the p99 step), so many_robots.toml leaves them off. With
``dmpc_conflicts`` two robots whose final plans run into each other move the same way (mpc/dmpc_pairs.py).

Parallelism (``dmpc_parallel="threads"``): ``mpc/parallel.py`` has the mechanism and its measurements. The
local parameters of a step are built once (mpc/local_params.py), the C_i checks in one call (LocalNLP.costs).
Which best responses an iteration keeps (lines 5-6 and the repairs) is mpc/dmpc_keep.py.
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numpy as np

from mpc.cmpc import IBRResult, PredictFn, finite_prediction
from mpc.config import MPCConfig
from mpc.dmpc_keep import PlanKeeper
from mpc.dmpc_pairs import pair_moves
from mpc.dmpc_start import initial_strategy
from mpc.dynamics import braking, rollout_numpy
from mpc.fallback import Start
from mpc.local_params import LocalParams
from mpc.nlp import JointNLP, LocalNLP, StepData
from mpc.parallel import cores, run_in_threads
from mpc.solvers import Solution, better


class _Update(NamedTuple):
    """One iteration's lines 3-10: the plans kept, their multipliers, and what it took."""

    accels: np.ndarray  # (M, H, 2) u^(j)
    lam_x: np.ndarray | None  # (M, H, 2) multipliers of the kept plans (None until a plan is kept)
    lam_g: np.ndarray | None
    failure: str  # the first failed local solve's status, "" if none failed
    solved: bool  # at least one local solve succeeded
    solves: int
    solver_iterations: int


class DMPC:
    """Algorithm 2 for a fixed problem size; the local NLP (shared by all robots) is built once, here."""

    def __init__(self, cfg: MPCConfig, n_robots: int, n_humans: int):
        self.cfg, self.n_robots, self.n_humans = cfg, n_robots, n_humans
        self.local = LocalNLP(cfg, n_robots, n_humans)
        self._keeper = PlanKeeper(cfg, self.local, n_robots)
        # F_t of the final plan (the common currency of CMPC and DMPC) and the heading start's test; solved
        # only by the pair moves, so its solver is built only for them.
        self.joint = JointNLP(cfg, n_robots, n_humans, solver=cfg.dmpc_pairs or cfg.dmpc_conflicts)
        self._pool: ThreadPoolExecutor | None = None  # made on first use with dmpc_parallel="threads"
        # Threads besides the caller's for the local solves: one per further core, at most one per robot.
        self._helpers = max(1, min(n_robots, cores()) - 1)

    def build_all(self) -> None:
        """Build every solver instance a solve may call, not only those the first step needs."""
        self.local.build_all()
        if self.cfg.dmpc_pairs or self.cfg.dmpc_conflicts:
            self.joint.build_all()

    def close(self) -> None:
        """Stop the solver threads; a later solve starts them again."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def _solve_all(
        self, jobs: list[tuple[int, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None, bool]]
    ) -> list[Solution]:
        """``LocalNLP.solve`` of every job, results in the jobs' order.

        With ``dmpc_parallel="threads"``, ``mpc.parallel.run_in_threads``. The jobs are for distinct robots,
        so no solver instance runs in two threads at once.
        """
        if self.cfg.dmpc_parallel != "threads" or len(jobs) < 2:
            return [self.local.solve(*job) for job in jobs]
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=self._helpers)
        return run_in_threads(self._pool, self._helpers, self.local.solve, jobs)

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
        cfg = self.cfg
        t0 = time.perf_counter()
        pred_shape = (cfg.horizon, self.n_humans, 2)
        # Indices of the active robots; np.ndarray (as in _restart) so its items pass where an int is taken.
        moving: np.ndarray = np.flatnonzero(np.asarray(data.active, dtype=bool))
        if cfg.dmpc_order == "nearest_first":  # Gauss-Seidel's order, the same in every round of the step
            distances = np.linalg.norm(data.states[moving, :2] - data.reference_targets()[moving], axis=1)
            moving = moving[np.argsort(distances, kind="stable")]
        accels, first_prediction = initial_strategy(cfg, self.joint, data, predict, start, moving)
        positions = rollout_numpy(data.states, accels, cfg.dt)[0]
        lam_x = None if start.lam_x is None else start.lam_x.copy()  # None from braking, heading or not
        lam_g = None if start.lam_g is None else start.lam_g.copy()
        step = self.local.step_params(data)  # what the local parameters share across the iterations
        status, converged, first_failure = "ok", False, ""
        used, predictions, potentials = None, [], []
        solves = solver_iterations = iterations = 0
        for j in range(1, cfg.j_max + 1):
            iterations = j
            prediction = (
                first_prediction  # made for these very plans by initial_strategy
                if j == 1 and first_prediction is not None
                else finite_prediction(predict(positions.transpose(1, 0, 2)), pred_shape)
            )
            if prediction is None:
                status = "nan_prediction"
                break
            predictions.append(prediction)
            # Lines 3-10: the robots' best responses and the plans they keep (cfg.dmpc_update).
            update = self._update(
                step, moving, positions, prediction, accels, lam_x, lam_g, start.first_solve(j)
            )
            new_accels, lam_x, lam_g = update.accels, update.lam_x, update.lam_g
            solves += update.solves
            solver_iterations += update.solver_iterations
            first_failure = first_failure or update.failure
            solved_now = update.solved
            if solved_now:
                used = prediction
            # Lines 12-16: the epsilon-Nash check against the others' new plans. An iteration in which every
            # local solve failed proves nothing, so it cannot end the loop as converged.
            new_positions = rollout_numpy(data.states, new_accels, cfg.dt)[0]
            if cfg.dmpc_stop == "no_improvement":
                # No robot kept a new plan: no best response to u^(j-1) improves by epsilon (u^(j) = u^(j-1)).
                converged = solved_now and np.array_equal(new_accels, accels)
            else:
                converged = solved_now and self._at_nash(
                    step, moving, accels, new_accels, new_positions, prediction
                )
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
        if used is None:
            # Nothing solved: the step applies its fallback, ``start`` (what the controller labels it),
            # not a heading u^(0), which ignores the humans. Else u^(0) is start.accels already.
            accels = start.accels.copy()
            positions = rollout_numpy(data.states, accels, cfg.dt)[0]
        result = IBRResult(
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
        if cfg.dmpc_pairs or cfg.dmpc_conflicts:  # within the step's time limit, as the loop above
            return pair_moves(self.joint, data, result, until=t0 + cfg.time_limit_s)
        return result

    def _update(
        self,
        step: LocalParams,
        moving: np.ndarray,
        positions: np.ndarray,
        prediction: np.ndarray,
        accels: np.ndarray,
        lam_x: np.ndarray | None,
        lam_g: np.ndarray | None,
        flags: dict[str, bool],
    ) -> _Update:
        """Lines 3-10 of iteration j from the plans ``accels`` of iteration j-1 (positions ``(M, H, 2)``),
        as ``cfg.dmpc_update`` says (module docstring)."""
        rule, data = self.cfg.dmpc_update, step.data
        if rule == "gauss_seidel":
            return self._sweep(step, moving, positions, prediction, accels, lam_x, lam_g, flags)
        # Line 4: every robot's best response to the others' plans of iteration j-1 (parallel).
        params = dict(zip(moving, step.rows(moving, positions, prediction), strict=True))
        sols, n_solves, n_iterations = self._best_responses(data, moving, params, accels, lam_x, lam_g, flags)
        if rule == "jacobi":
            kept = self._keeper.improvements(moving, params, accels, sols, lam_x, lam_g)
        elif rule == "relaxed":
            kept = self._keeper.relaxed(moving, params, accels, sols, lam_x, lam_g)
        else:
            kept = self._keeper.in_turn(step, moving, params, prediction, accels, sols, lam_x, lam_g)
        solved = any(s.success for s in sols)
        return _Update(*kept, solved, n_solves, n_iterations)

    def _sweep(
        self,
        step: LocalParams,
        moving: np.ndarray,
        positions: np.ndarray,
        prediction: np.ndarray,
        accels: np.ndarray,
        lam_x: np.ndarray | None,
        lam_g: np.ndarray | None,
        flags: dict[str, bool],
    ) -> _Update:
        """Gauss-Seidel: the robots best-respond one after the other, in the order of ``moving``
        (``cfg.dmpc_order``), each to the latest plans, and keep an improvement of at least epsilon at once
        (lines 4-6 for one robot at a time)."""
        accels, positions, data = accels.copy(), positions.copy(), step.data
        failure, solved, solves, solver_iterations = "", False, 0, 0
        for i in moving:
            one = np.array([i])
            params = {i: step.row(i, positions, prediction)}
            sols, n_solves, n_iterations = self._best_responses(
                data, one, params, accels, lam_x, lam_g, flags
            )
            accels, lam_x, lam_g, failed = self._keeper.improvements(one, params, accels, sols, lam_x, lam_g)
            positions[i] = rollout_numpy(data.states[one], accels[one], self.cfg.dt)[0][0]
            failure = failure or failed
            solved = solved or sols[0].success
            solves += n_solves
            solver_iterations += n_iterations
        return _Update(accels, lam_x, lam_g, failure, solved, solves, solver_iterations)

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

    def _at_nash(
        self,
        step: LocalParams,
        moving: np.ndarray,
        accels: np.ndarray,
        new_accels: np.ndarray,
        new_positions: np.ndarray,
        prediction: np.ndarray,
    ) -> bool:
        """Lines 12-16: no robot's new plan is worse, by more than epsilon, than its old one against the
        others' new plans. It can hold after the first iteration (every robot's start already near its best
        response), and the step then ends with one round of solves, as Algorithm 2 reads."""
        new_params = list(step.rows(moving, new_positions, prediction))
        checks = self.local.costs(
            [new_accels[i] for i in moving] + [accels[i] for i in moving], new_params + new_params
        ).reshape(2, len(moving))
        return bool(np.all(checks[0] <= checks[1] + self.cfg.epsilon))
