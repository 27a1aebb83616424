"""The solvers behind the NLPs of mpc/nlp.py: Fatrop with IPOPT as its fallback (or IPOPT alone), their
CasADi options, and what a solve returns.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from mpc import compile_cache
from mpc.config import MPCConfig
from mpc.fastcall import BufferedFunction

# Statuses after which the returned point is a solution we use (IPOPT's names; a Fatrop success is reported
# as "Solve_Succeeded" too).
SOLVED = frozenset({"Solve_Succeeded", "Solved_To_Acceptable_Level"})
_BUILD_LOCK = threading.Lock()


@dataclass(frozen=True)
class Solution:
    """One solve: Fatrop's point, or IPOPT's when Fatrop failed or (``explore``) IPOPT found a lower cost."""

    accels: np.ndarray  # (M, H, 2) joint, or (H, 2) local
    cost: float  # F (joint) or C_i (local), unscaled
    status: str  # "Solve_Succeeded" or IPOPT's return status
    success: bool  # status in SOLVED and the result is finite
    iterations: int  # solver iterations (Fatrop's and IPOPT's together)
    solver: str  # "fatrop" or "ipopt": which one produced the point
    lam_x: np.ndarray = field(repr=False)  # multipliers, for the next warm start
    lam_g: np.ndarray = field(repr=False)


def better(a: Solution, b: Solution) -> Solution:
    """The successful solution with the lower cost (``a`` when neither succeeded)."""
    if b.success and (not a.success or b.cost < a.cost):
        return b
    return a


def build_nlpsol(name: str, plugin: str, nlp: dict, options: dict, jit: bool) -> ca.Function:
    """``casadi.nlpsol``; with ``jit``, compiled with gcc through the persistent compile cache
    (mpc/compile_cache.py: compiled once per machine, then loaded in milliseconds by every process)."""
    if jit:
        return compile_cache.nlpsol(name, plugin, nlp, options)
    return ca.nlpsol(name, plugin, nlp, options)


def ipopt_options(cfg: MPCConfig, warm: bool) -> dict:
    """IPOPT through CasADi: silent, exact Hessian, tolerances and limits from the config.

    ``warm``: start from given primal and dual values (``warm_start_init_point``) with a small barrier
    parameter, since the shifted previous solution is already close to optimal. Measured on 185 recorded
    steps (3 robots, 7 humans): mu_init 1e-3 and 1e-5 tie (4.6 ms, ~10 iterations), 1e-2 is 20 % slower;
    mu_strategy adaptive and no NLP scaling are slower; L-BFGS is 10x slower and fails; tol 1e-4 saves 10 %
    but stops short of the optimum (F up to 20 higher).
    """
    opts = {
        "print_time": False,
        # Multipliers of the parameters are never used; skipping them also avoids differentiating the
        # reference trajectory (Eq. 8), whose norm is not differentiable once the reference sits on the goal.
        "calc_lam_p": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.tol": cfg.solver_tol,
        "ipopt.acceptable_tol": max(1e2 * cfg.solver_tol, 1e-4),
        "ipopt.max_iter": cfg.solver_max_iter,
        "ipopt.max_wall_time": cfg.time_limit_s,
    }
    if warm:
        opts.update(
            {
                "ipopt.warm_start_init_point": "yes",
                "ipopt.mu_init": 1e-3,
                "ipopt.warm_start_bound_push": 1e-6,
                "ipopt.warm_start_mult_bound_push": 1e-6,
            }
        )
    return opts


def fatrop_options(cfg: MPCConfig) -> dict:
    """Fatrop through CasADi: the NLP as one dense stage (``structure_detection`` none: single shooting has
    no stage structure to exploit, and 8-24 variables do not need it), silent, errors as statuses.

    Fatrop takes no dual warm start, only the primal guess. Measured on 2380 recorded local problems:
    mu_init 1e-2 takes 8.7 iterations, 1e-3 and 1e-1 9.7; tol 1e-5 saves 3 % (benchmarks/solvers.py).
    """
    return {
        "structure_detection": "none",
        "print_time": False,
        "calc_lam_p": False,
        "error_on_fail": False,
        "fatrop": {
            "print_level": 0,
            "tol": cfg.solver_tol,
            "mu_init": 1e-2,
            "max_iter": cfg.solver_max_iter,
        },
    }


class _Solver:
    """The solver(s) of one NLP: Fatrop and IPOPT together (``cfg.solver="fatrop"``), or IPOPT alone.

    With Fatrop, a solve goes to Fatrop, and to IPOPT (warm when given multipliers) only if Fatrop fails. A
    solve with ``explore`` (the first solve of a step that starts from braking: an episode's first step, or
    one after failures) goes to both, and the lower cost wins. From a standing start the NLP has several
    local minima, and the one the first step picks sets the robots' formation for the episode:
    ``benchmarks/first_step.py`` (40 CMPC episodes, social_lstm_eth, 7 humans; docs/results.md) has Fatrop
    alone take the first step elsewhere in 27-40 of 40, into 37.5 % collisions against 27.5 % under the v1
    conventions and 0.6-2.4 s more travel under the paper's; exploring with both gives IPOPT's episodes to
    within 0.1 s of travel, at Fatrop's speed.

    The cold IPOPT is built with the solver (the first step needs it), the warm one when first needed (a
    failed Fatrop solve); IPOPT is compiled (``jit``) only when it is the solver.
    ``ipopt_extra``: IPOPT-only settings the NLP needs (the coupled NLP's L-BFGS Hessian); they make IPOPT
    the solver. Separate ``_Solver`` objects of the same NLP can run in separate threads (CasADi releases
    the GIL during a call); one object must not be called from two threads at once (a solver's memory is
    per instance: IPOPT segfaults).
    """

    def __init__(self, name: str, nlp: dict, cfg: MPCConfig, ipopt_extra: dict | None = None):
        self.cfg = cfg
        self._name, self._nlp, self._ipopt_extra = name, nlp, ipopt_extra or {}
        self.primary = "ipopt" if cfg.solver == "ipopt" or self._ipopt_extra else "fatrop"
        self._fatrop = None
        self._ipopt_instances: dict[bool, BufferedFunction] = {}
        if self.primary == "fatrop":
            fatrop = build_nlpsol(name, "fatrop", nlp, fatrop_options(cfg), cfg.jit)
            self._fatrop = BufferedFunction(fatrop)
            # every episode's first step explores with the cold IPOPT too: built here, with the NLP, not
            # inside the first episode's first timed step (it made that step 2-5x an episode's later first
            # steps)
            self._ipopt(warm=False)
        else:
            self._ipopt(warm=False)
            if cfg.warm_start:
                self._ipopt(warm=True)

    def build_all(self) -> None:
        """Build the warm IPOPT too, which a solve otherwise builds when Fatrop first fails (25-75 ms at 3
        robots and 7-20 humans): a controller prepared before a real robot's loop builds nothing in a step."""
        if self.cfg.warm_start:
            self._ipopt(warm=True)

    def _ipopt(self, warm: bool) -> BufferedFunction:
        if warm not in self._ipopt_instances:
            jit = self.cfg.jit and self.primary == "ipopt"
            options = ipopt_options(self.cfg, warm=warm) | self._ipopt_extra
            # DMPC's threads may build their robots' IPOPT at the same moment, from the same SX graph, whose
            # reference counts are not atomic: one build at a time.
            with _BUILD_LOCK:
                solver = build_nlpsol(self._name, "ipopt", self._nlp, options, jit)
            self._ipopt_instances[warm] = BufferedFunction(solver)
        return self._ipopt_instances[warm]

    def solve(
        self, x0, p, lbx, ubx, lbg, ubg, lam_x0=None, lam_g0=None, explore: bool = False
    ) -> tuple[dict, dict]:
        """Returns CasADi's output and ``{"status", "iterations", "solver"}``."""
        args = {"x0": x0, "p": p, "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}
        warm = self.cfg.warm_start and lam_x0 is not None
        if self._fatrop is None:
            return self._solve_ipopt(args, lam_x0, lam_g0, warm)
        t0 = time.perf_counter()
        out = self._fatrop.call(args)
        stats = self._fatrop.stats()
        info = {"status": "Solve_Succeeded", "iterations": int(stats["iter_count"]), "solver": "fatrop"}
        if time.perf_counter() - t0 > self.cfg.time_limit_s:
            # Fatrop has no wall-time limit: IPOPT's max_wall_time rule, applied after the fact.
            return out, info | {"status": "Maximum_WallTime_Exceeded"}
        if not stats["success"]:
            info["status"] = "Fatrop_Failed"
        elif not explore:
            return out, info
        other, other_info = self._solve_ipopt(args, lam_x0, lam_g0, warm)
        iterations = info["iterations"] + other_info["iterations"]
        cost = _cost(out, info)
        if math.isfinite(cost) and cost <= _cost(other, other_info) + 1e-9 * max(1.0, abs(cost)):
            # Fatrop's, also when IPOPT reached the same minimum up to rounding.
            return out, info | {"iterations": iterations}
        return other, other_info | {"iterations": iterations}

    def _solve_ipopt(self, args: dict, lam_x0, lam_g0, warm: bool) -> tuple[dict, dict]:
        solver = self._ipopt(warm)
        if warm:
            args = args | {"lam_x0": np.ravel(lam_x0), "lam_g0": np.ravel(lam_g0)}
        out = solver.call(args)
        stats = solver.stats()
        return out, {
            "status": str(stats["return_status"]),
            "iterations": int(stats["iter_count"]),
            "solver": "ipopt",
        }


def _cost(out: dict, info: dict) -> float:
    """The objective of a solve's point, +inf unless the solve succeeded with finite numbers."""
    f = float(out["f"][0])
    finite = math.isfinite(f) and bool(np.all(np.isfinite(out["x"])))
    return f if info["status"] in SOLVED and finite else math.inf
