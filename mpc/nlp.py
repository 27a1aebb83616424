"""The joint NLP (Eq. 17, minimise the potential F) and the per-robot local NLP (Eq. 5, minimise C_i).

Built once per problem size (robots M, humans N_h) as CasADi SX graphs (MX when a coupled humans model is too
big to expand, mpc/coupled.py) with parameters for everything that changes between solves: current states,
previously applied actions, goals, per-pair flocking weights, the safety margin of every human at every step,
the humans' predicted positions and (local NLP) the other robots' planned positions. Single shooting: the only
decision variables are the accelerations, whose bounds (Eq. 6) are simple bounds; the velocity bounds (Eq. 6)
are linear constraints ``-v_max <= v_t + dt cumsum(a) <= v_max``. A robot pinned on its goal
(``on_goal="brake"``) keeps its place in the NLP (same structure at every step) with its controls fixed to
braking through equal lower and upper bounds (IPOPT removes such variables from the problem, Fatrop keeps them
at the bound).

Array layout: a plan is ``(M, H, 2)`` accelerations, row-major flattened into the decision vector; the
humans' predictions ``(H, N_h, 2)``, their margins ``(H, N_h)`` and the other robots' positions
``(M-1, H, 2)`` travel row-major flattened. ``reshape(v, 2, -1)`` (column-major) turns each into the
``(2, .)`` blocks of mpc/costs.py.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import casadi as ca
import numpy as np

from mpc import costs
from mpc.config import MPC_BOUNDS, MPC_LEAST, MPCConfig
from mpc.dynamics import braking
from mpc.errors import MPCConfigError
from mpc.fastcall import BufferedFunction
from mpc.local_params import LocalParams, flock_distances
from mpc.sizes import check_team
from mpc.solvers import SOLVED, Solution, _Solver, better
from mpc.step_data import StepData


def _blocks(flat: ca.SX, n_blocks: int, horizon: int) -> list[ca.SX]:
    """``n_blocks`` ``(2, H)`` matrices from a row-major flat ``(n_blocks, H, 2)`` vector."""
    mat = ca.reshape(flat, 2, n_blocks * horizon)
    return [mat[:, b * horizon : (b + 1) * horizon] for b in range(n_blocks)]


def _solution(out: dict, stats: dict, cost_scale: float, shape: tuple[int, ...]) -> Solution:
    accels = out["x"].reshape(shape)
    cost = float(out["f"][0]) / cost_scale
    status = stats["status"]
    success = status in SOLVED and bool(np.all(np.isfinite(accels))) and math.isfinite(cost)
    return Solution(
        accels=accels,
        cost=cost,
        status=status,
        success=success,
        iterations=stats["iterations"],
        solver=stats["solver"],
        lam_x=out["lam_x"],
        lam_g=out["lam_g"],
    )


def _same_team(data: StepData, n_robots: int) -> None:
    """ValueError unless ``data`` is of the team the NLP was built for: a team of another size reached numpy
    as a parameter vector of the wrong length ("operands could not be broadcast together")."""
    if data.n_robots != n_robots:
        raise ValueError(
            f"StepData holds {data.n_robots} robots, but this NLP was built for {n_robots}: build the "
            "solver for the team's size"
        )


def check_solvable(cfg: MPCConfig) -> None:
    """``cfg``'s numbers within the bounds its NLP is built with (``MPC_BOUNDS``: rho = 1e300 made the exact
    Hessian Inf; ``MPC_LEAST``: delta = 1e-300 overflowed Eq. 7's goal weight; either way a Fatrop solve
    never returned), MPCConfigError naming the first one beyond. Checked here and as a run starts
    (pipelines.commands.simulate_checks), not by MPCConfig: a config read back from a sweep folder that ran
    well beyond a bound added since (rho = 2000, delta = 1e-200 with Table I's weights) runs nothing, and
    its --report-only and config show --from-sweep refused it."""
    for name, (most, unit) in MPC_BOUNDS.items():
        if getattr(cfg, name) > most:
            raise MPCConfigError(f"{name} must be at most {most:g}{unit}, got {getattr(cfg, name)!r}", name)
    for name, (least, unit) in MPC_LEAST.items():
        if getattr(cfg, name) < least:
            raise MPCConfigError(f"{name} must be at least {least:g}{unit}, got {getattr(cfg, name)!r}", name)


class FixedPredictions:
    """The humans' predicted positions are parameters: Eq. 17 as Algorithm 1 solves it."""

    def __init__(self, horizon: int, n_humans: int):
        self.n_params = 2 * horizon * n_humans

    def humans(self, p: ca.SX, robots_future: ca.SX) -> ca.SX:
        return p


class JointNLP:
    """Eq. 17: ``min_u F(u, s_H)`` over all robots' controls.

    ``humans_model`` says where the humans' positions ``s_H`` come from: by default they are parameters (the
    predictions of an IBR iteration); mpc/coupled.py passes models that compute them inside the NLP from the
    robots' planned positions. Its parameters (``extra`` below) close the parameter vector.
    """

    def __init__(
        self, cfg: MPCConfig, n_robots: int, n_humans: int, humans_model=None, *, solver: bool = True
    ):
        """``solver=False`` builds only the cost functions (``potential``, ``penalty``): the solver, which
        takes most of the build (4 of 4.4 s at 12 robots, and a gcc compile with ``jit``), is then built by
        the first ``solve``. DMPC evaluates F with this NLP and solves it only for its pair moves."""
        check_solvable(cfg)
        n_robots, n_humans = check_team(n_robots, n_humans)
        self.cfg, self.n_robots, self.n_humans = cfg, n_robots, n_humans
        h, m = cfg.horizon, n_robots
        self.n_pairs = m * (m - 1) // 2
        model = humans_model if humans_model is not None else FixedPredictions(h, n_humans)
        # SX (scalar graphs: fastest to evaluate) unless the humans model is too big to expand (a network).
        sym = getattr(model, "symbolic", ca.SX)
        u = sym.sym("u", 2 * h * m)
        p_state = sym.sym("states", 4 * m)
        p_last = sym.sym("last_actions", 2 * m)
        p_goal = sym.sym("goals", 2 * m)
        p_target = sym.sym("targets", 2 * m)
        p_slack = sym.sym("goal_slack", m)
        p_floc = sym.sym("floc_weights", self.n_pairs)
        # d_ij per pair only where they differ (flock_distance "goals"): the paper's NLP stays as it was
        p_dist = [sym.sym("flock_distances", self.n_pairs)] if cfg.flock_distance == "goals" else []
        p_margins = sym.sym("human_margins", h * n_humans)
        p_extra = sym.sym("humans_model", model.n_params)
        p = ca.vertcat(p_state, p_last, p_goal, p_target, p_slack, p_floc, *p_dist, p_margins, p_extra)
        states = ca.reshape(p_state, 4, m)
        lasts = ca.reshape(p_last, 2, m)
        goals = ca.reshape(p_goal, 2, m)
        targets = ca.reshape(p_target, 2, m)
        tracks = [
            costs.make_track(states[:, i], a, lasts[:, i], goals[:, i], cfg.dt, targets[:, i], p_slack[i])
            for i, a in enumerate(_blocks(u, m, h))
        ]
        # Robots' planned positions (H, M, 2) row-major: column h * M + m of a (2, H * M) matrix.
        robots_future = ca.vec(ca.horzcat(*[t.positions[:, k] for k in range(h) for t in tracks]))
        humans_flat = model.humans(p_extra, robots_future)
        humans = ca.reshape(humans_flat, 2, h * n_humans)
        margins = ca.reshape(p_margins, 1, h * n_humans)
        F = costs.potential(tracks, p_floc, humans, n_humans, cfg, margins, *p_dist)
        penalty = costs.collision_penalty(tracks, humans, n_humans, cfg, margins)
        g = ca.vertcat(*[ca.vec(t.velocities) for t in tracks])
        self.penalty_fn = ca.Function("penalty", [u, p], [penalty], ["u", "p"], ["penalty"])
        self.potential_fn = ca.Function("F", [u, p], [F], ["u", "p"], ["F"])
        self.humans_fn = ca.Function("humans", [u, p], [humans_flat], ["u", "p"], ["humans"])
        self._penalty, self._potential = (
            BufferedFunction(self.penalty_fn),
            BufferedFunction(self.potential_fn),
        )
        self._nlp = {"x": u, "p": p, "f": cfg.cost_scale * F, "g": g}
        self._ipopt_extra = getattr(model, "ipopt_options", None)
        self._built: _Solver | None = None
        if solver:
            self._solver()

    def _solver(self) -> _Solver:
        if self._built is None:
            name = f"joint_{self.n_robots}r_{self.n_humans}h"
            self._built = _Solver(name, self._nlp, self.cfg, self._ipopt_extra)
        return self._built

    def build_all(self) -> None:
        """Build every solver instance a solve may call (``_Solver.build_all``)."""
        self._solver().build_all()

    @property
    def first_solver(self) -> str:
        """The solver a solve goes to first: "fatrop" (IPOPT where Fatrop fails) or "ipopt" (alone: the
        config's choice, or a humans model with IPOPT-only options, a network's L-BFGS)."""
        return self._solver().primary

    def params(self, data: StepData, extra: np.ndarray) -> np.ndarray:
        """The parameter vector for ``data``; ``extra``: the humans model's parameters (by default the
        predictions ``(H, N_h, 2)``)."""
        _same_team(data, self.n_robots)
        return np.concatenate(
            [
                data.states.ravel(),
                data.last_actions.ravel(),
                data.goals.ravel(),
                data.reference_targets().ravel(),
                data.goal_slacks(),
                data.floc_weights(self.cfg.pair_floc_weight(data.n_robots), self.cfg.flock_range),
                *flock_distances(data, self.cfg),
                data.margins(self.cfg, self.n_humans),
                np.asarray(extra, dtype=float).ravel(),
            ]
        )

    def bounds(self, data: StepData) -> tuple[np.ndarray, np.ndarray]:
        """Acceleration bounds (Eq. 6); a parked robot's controls are pinned to braking."""
        _same_team(data, self.n_robots)
        cfg = self.cfg
        lbx = np.full((self.n_robots, cfg.horizon, 2), -cfg.a_max)
        ubx = np.full((self.n_robots, cfg.horizon, 2), cfg.a_max)
        parked = ~np.asarray(data.active, dtype=bool)
        if parked.any():
            brake = braking(data.states[parked], cfg.horizon, cfg.dt, cfg.a_max)
            lbx[parked] = brake
            ubx[parked] = brake
        return lbx.ravel(), ubx.ravel()

    def potential(self, accels: np.ndarray, data: StepData, extra: np.ndarray) -> float:
        """F (Eq. 16) of the plan ``accels`` ``(M, H, 2)``."""
        return float(self._potential(accels, self.params(data, extra))[0][0])

    def penalty(self, accels: np.ndarray, data: StepData, extra: np.ndarray) -> float:
        """The collision part of F (robot-human and robot-robot penalties, weighted) for ``accels``."""
        return float(self._penalty(accels, self.params(data, extra))[0][0])

    def humans(self, accels: np.ndarray, data: StepData, extra: np.ndarray) -> np.ndarray:
        """The humans' positions ``(H, N_h, 2)`` the NLP sees for the plan ``accels``."""
        flat = np.asarray(self.humans_fn(np.ravel(accels), self.params(data, extra)))
        return flat.reshape(self.cfg.horizon, self.n_humans, 2)

    def solve(
        self,
        data: StepData,
        extra: np.ndarray,
        accels0: np.ndarray,
        lam_x0: np.ndarray | None = None,
        lam_g0: np.ndarray | None = None,
        explore: bool = False,
        bounds: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> Solution:
        """Solve from the initial guess ``accels0`` ``(M, H, 2)`` (and multipliers, when warm-starting);
        ``explore``: with both solvers, keeping the lower cost (mpc/solvers.py ``_Solver``); ``bounds``:
        the flat acceleration bounds, ``bounds(data)`` by default."""
        lbx, ubx = self.bounds(data) if bounds is None else bounds
        x0 = np.clip(np.ravel(accels0), lbx, ubx)
        v = self.cfg.v_max
        p = self.params(data, extra)
        out, stats = self._solver().solve(x0, p, lbx, ubx, -v, v, lam_x0, lam_g0, explore)
        return _solution(out, stats, self.cfg.cost_scale, (self.n_robots, self.cfg.horizon, 2))

    def solve_group(
        self, data: StepData, extra: np.ndarray, accels: np.ndarray, free: np.ndarray
    ) -> Solution:
        """Eq. 17 over the controls of the robots ``free`` (``(M,)`` bool) only, every other robot's plan
        pinned to its row of ``accels`` ``(M, H, 2)`` (equal bounds, as a parked robot's), from ``accels``:
        a joint best response of a group (mpc/dmpc_pairs.py)."""
        lbx, ubx = (b.reshape(accels.shape) for b in self.bounds(data))
        pinned = ~np.asarray(free, dtype=bool)
        lbx[pinned] = ubx[pinned] = accels[pinned]
        return self.solve(data, extra, accels, bounds=(lbx.ravel(), ubx.ravel()))

    def solve_multi_start(
        self,
        data: StepData,
        extra: np.ndarray,
        accels0: np.ndarray,
        lam_x0: np.ndarray | None = None,
        lam_g0: np.ndarray | None = None,
        *,
        restart: bool,
        explore: bool = False,
    ) -> tuple[Solution, int, int]:
        """``solve``, then (when ``restart`` and ``cfg.multi_start``) once more from braking if the first
        solution failed or still pays more than ``cfg.restart_penalty`` of collision penalty: a warm start can
        sit in a poor local minimum as a gap closes. Returns the better solution, the solves and solver
        iterations spent."""
        sol = self.solve(data, extra, accels0, lam_x0, lam_g0, explore)
        cfg = self.cfg
        if not (restart and cfg.multi_start):
            return sol, 1, sol.iterations
        if sol.success and self.penalty(sol.accels, data, extra) <= cfg.restart_penalty:
            return sol, 1, sol.iterations
        other = self.solve(data, extra, braking(data.states, cfg.horizon, cfg.dt, cfg.a_max))
        return better(sol, other), 2, sol.iterations + other.iterations


class LocalNLP:
    """Eq. 5 for one robot: ``min_{u_i} C_i(u_i, u_-i)`` with the other robots' planned positions given.

    The same instance serves every robot: who "i" is lives entirely in the parameters.
    """

    def __init__(self, cfg: MPCConfig, n_robots: int, n_humans: int):
        check_solvable(cfg)
        n_robots, n_humans = check_team(n_robots, n_humans, least_robots=1)
        self.cfg, self.n_robots, self.n_humans = cfg, n_robots, n_humans
        h, n_others = cfg.horizon, n_robots - 1
        u = ca.SX.sym("u", 2 * h)
        p_state = ca.SX.sym("state", 4)
        p_last = ca.SX.sym("last_action", 2)
        p_goal = ca.SX.sym("goal", 2)
        p_target = ca.SX.sym("target", 2)
        p_slack = ca.SX.sym("goal_slack", 1)
        p_floc = ca.SX.sym("floc_weights", n_others)
        p_dist = [ca.SX.sym("flock_distances", n_others)] if cfg.flock_distance == "goals" else []
        p_others = ca.SX.sym("others", 2 * h * n_others)
        p_margins = ca.SX.sym("human_margins", h * n_humans)
        p_humans = ca.SX.sym("humans", 2 * h * n_humans)
        p = ca.vertcat(
            p_state, p_last, p_goal, p_target, p_slack, p_floc, *p_dist, p_others, p_margins, p_humans
        )
        track = costs.make_track(p_state, ca.reshape(u, 2, h), p_last, p_goal, cfg.dt, p_target, p_slack)
        others = _blocks(p_others, n_others, h)
        humans = ca.reshape(p_humans, 2, h * n_humans)
        weights = [p_floc[k] for k in range(n_others)]
        margins = ca.reshape(p_margins, 1, h * n_humans)
        distances = [p_dist[0][k] for k in range(n_others)] if p_dist else None
        C = costs.robot_cost(track, others, weights, humans, n_humans, cfg, margins, distances)
        penalty = cfg.w_coll * costs.human_collision_cost(
            track.positions, track.velocities, humans, n_humans, cfg, margins
        )
        for positions_j in others:
            penalty = penalty + cfg.w_coll * costs.robot_collision_cost(track.positions, positions_j, cfg)
        penalty = costs.dense(penalty)  # alone and with no humans: structurally empty (costs.dense)
        g = ca.vec(track.velocities)
        self.cost_fn = ca.Function("C", [u, p], [C], ["u", "p"], ["C"])
        self.penalty_fn = ca.Function("penalty", [u, p], [penalty], ["u", "p"], ["penalty"])
        # Called from the thread that runs DMPC only (the solves may run in others).
        self._cost, self._penalty = BufferedFunction(self.cost_fn), BufferedFunction(self.penalty_fn)
        self._maps: dict[tuple[str, int], BufferedFunction] = {}  # (function, n) -> its map over n pairs
        nlp = {"x": u, "p": p, "f": cfg.cost_scale * C, "g": g}
        # One solver instance per robot when DMPC runs the robots' solves in threads (an instance must not
        # be called from two threads at once); one shared by every robot otherwise (a third of the builds,
        # which matters with jit).
        if cfg.dmpc_parallel == "threads":
            self._solvers = [_Solver(f"local_{n_robots}r_{n_humans}h_{i}", nlp, cfg) for i in range(n_robots)]
        else:
            self._solvers = [_Solver(f"local_{n_robots}r_{n_humans}h", nlp, cfg)] * n_robots

    def build_all(self) -> None:
        """Build every solver instance a solve may call (``_Solver.build_all``), once per distinct solver."""
        for solver in {id(s): s for s in self._solvers}.values():
            solver.build_all()

    def step_params(self, data: StepData) -> LocalParams:
        """The step's parameters of every robot, for any plans of the others (mpc/local_params.py)."""
        _same_team(data, self.n_robots)
        return LocalParams.build(data, self.cfg, self.n_humans)

    def params(self, i: int, data: StepData, positions: np.ndarray, humans: np.ndarray) -> np.ndarray:
        """Parameters for robot ``i`` given all robots' planned positions ``(M, H, 2)`` (row ``i`` unused).
        A loop over a step's iterations builds ``step_params`` once instead."""
        return self.step_params(data).row(i, positions, humans)

    def cost(self, accels_i: np.ndarray, params: np.ndarray) -> float:
        """C_i of robot ``i``'s plan ``accels_i`` ``(H, 2)`` with ``params`` from :meth:`params`."""
        return float(self._cost(accels_i, params)[0][0])

    def penalty(self, accels_i: np.ndarray, params: np.ndarray) -> float:
        """The collision part of C_i (weighted robot-human and robot-robot penalties)."""
        return float(self._penalty(accels_i, params)[0][0])

    def costs(self, plans: Sequence[np.ndarray], params: Sequence[np.ndarray]) -> np.ndarray:
        """``cost`` of each (plan, parameters) pair, in one call of C_i mapped over them."""
        return self._batched(self.cost_fn, plans, params)

    def penalties(self, plans: Sequence[np.ndarray], params: Sequence[np.ndarray]) -> np.ndarray:
        """``penalty`` of each (plan, parameters) pair, in one call."""
        return self._batched(self.penalty_fn, plans, params)

    def _batched(
        self, function: ca.Function, plans: Sequence[np.ndarray], params: Sequence[np.ndarray]
    ) -> np.ndarray:
        """``function`` of each pair through ``function.map(n)``: a serial map runs the same evaluation per
        column, so each value equals a single call's bit for bit, at one Python round trip for all n."""
        n = len(plans)
        if n != len(params):
            raise ValueError(f"{n} plans but {len(params)} parameter vectors")
        if n == 0:
            return np.zeros(0)
        key = (function.name(), n)
        if key not in self._maps:
            self._maps[key] = BufferedFunction(function.map(n))
        # Column k of the mapped inputs is pair k: row-major (n, .) stacks are those columns in order.
        return self._maps[key](np.stack([np.ravel(a) for a in plans]), np.stack(params))[0]

    def solve(
        self,
        i: int,
        params: np.ndarray,
        accels0: np.ndarray,
        lam_x0: np.ndarray | None = None,
        lam_g0: np.ndarray | None = None,
        explore: bool = False,
    ) -> Solution:
        """Robot ``i``'s solve with ``params`` from :meth:`params` (``explore``: see ``JointNLP.solve``)."""
        cfg = self.cfg
        x0 = np.clip(np.ravel(accels0), -cfg.a_max, cfg.a_max)
        out, stats = self._solvers[i].solve(
            x0, params, -cfg.a_max, cfg.a_max, -cfg.v_max, cfg.v_max, lam_x0, lam_g0, explore
        )
        return _solution(out, stats, cfg.cost_scale, (cfg.horizon, 2))
