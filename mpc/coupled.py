"""Beyond the paper: the predictor inside the joint NLP (``coupling="nlp"``), so one solve accounts for how
the humans react to the robots' plan.

The paper calls Eq. 17 with the recursive predictor inside "computationally intractable" and iterates
instead (Algorithm 1). Here the predictor's CasADi twin (``Predictor.to_casadi``) is composed with the robots'
dynamics: ``s_H = f(context, robots_future(u))``. What depends only on the observed past is computed once per
control step, numerically (``context = predictor.encode(...)``), and enters as a parameter; only the
horizon is symbolic. The NLP is built once per problem size, like every other.

Two models of the humans (``MPCConfig.coupled_mode``):

* ``"exact"``: ``f`` itself inside the NLP. One solve per step.
* ``"first_order"``: ``f`` linearised around the current plan ``r0``: ``s_H ~ f(r0) + J (r - r0)``, with the
  value and the Jacobian ``J = df/dr`` evaluated numerically once per iteration and passed as parameters; the
  NLP then costs about as much as one with fixed predictions. Re-linearise at the new plan and solve again
  until ``|F^(j) - F^(j-1)| <= xi`` or ``j_max``, ``F`` evaluated with the true ``f``. A fixed point of this
  iteration (``u`` optimal for the model linearised at ``u``) is a stationary point of the exact coupled
  problem, since the linear model matches ``f`` and its first derivative there; IBR's fixed points (the
  predictions held constant) ignore that derivative.
* ``"auto"`` (default): exact when ``f`` expands into at most ``EXPAND_MAX_NODES`` scalar nodes (constant
  velocity, small models), first-order otherwise.

Measured (an untrained Social-LSTM of the default size, soft pooling, 7 humans, 3 robots, H = 4, closed loop
on the shared 2-core machine under load): exact with ``f`` expanded to SX: 97 s to build, every solve past
the 1 s limit; exact as an MX call node with IPOPT's exact Hessian: ~80 ms an IPOPT iteration, solves past
1 s; exact as MX with L-BFGS: median ~280 ms, some solves at max_iter; first-order: median ~90 ms, p95
~120-145 ms (one Jacobian of f costs ~15 ms, f itself ~1 ms); Algorithm 1 with the same predictor: ~65 ms.

With the constant-velocity predictor ``J = 0``: both modes reduce to one solve with fixed predictions (the
first-order loop sees the same linear model twice and stops, as Algorithm 1 does on a repeated prediction).
"""

from __future__ import annotations

import math
import time
from typing import Final

import casadi as ca
import numpy as np

from mpc.cmpc import IBRResult, finite_prediction, joint_result
from mpc.config import MPCConfig
from mpc.dynamics import rollout_numpy
from mpc.fallback import Start
from mpc.nlp import JointNLP, StepData

# A predictor whose expanded scalar graph is larger than this stays an MX call node inside the NLP.
EXPAND_MAX_NODES: Final[int] = 20_000


def expand_if_small(function: ca.Function) -> ca.Function | None:
    """``function`` as an SX function when its scalar graph has at most ``EXPAND_MAX_NODES`` nodes."""
    expanded = function if function.is_a("SXFunction") else function.expand()
    return expanded if expanded.n_nodes() <= EXPAND_MAX_NODES else None


class ExactPredictor:
    """Humans model of the joint NLP: the predictor's CasADi function of (context, robots_future).

    A small predictor (constant velocity, toys) is expanded into the NLP's SX graph: no call overhead and
    exact second derivatives. A network is not: expanding the default Social-LSTM (soft pooling, 7 humans,
    3 robots, H = 4) gives millions of scalar nodes, a 97 s build and more than 1 s a solve; kept as an MX
    call node with IPOPT's exact Hessian it still costs ~80 ms an IPOPT iteration. Networks therefore stay
    MX with IPOPT's limited-memory (L-BFGS) Hessian, which needs only the network's gradient.
    """

    def __init__(self, function: ca.Function, context_size: int, expanded: ca.Function | None):
        """``expanded``: ``expand_if_small(function)``, computed once by the caller."""
        self.n_params = context_size
        if expanded is not None:
            self.function, self.symbolic, self.ipopt_options = expanded, ca.SX, {}
        else:
            self.function, self.symbolic = function, ca.MX
            self.ipopt_options = {"ipopt.hessian_approximation": "limited-memory"}

    def humans(self, p, robots_future):
        return self.function(p, robots_future)


class FirstOrderPredictor:
    """Humans model ``f(r0) + J (r - r0)``; parameters ``[f(r0) | J row-major | r0]``."""

    def __init__(self, n_out: int, n_in: int):
        self.n_out, self.n_in = n_out, n_in
        self.n_params = n_out + n_out * n_in + n_in

    def humans(self, p: ca.SX, robots_future: ca.SX) -> ca.SX:
        value = p[: self.n_out]
        jac = ca.reshape(p[self.n_out : self.n_out + self.n_out * self.n_in], self.n_in, self.n_out).T
        r0 = p[self.n_out + self.n_out * self.n_in :]
        return value + ca.mtimes(jac, robots_future - r0)

    @staticmethod
    def params(value: np.ndarray, jac: np.ndarray, r0: np.ndarray) -> np.ndarray:
        return np.concatenate([np.ravel(value), np.ravel(jac), np.ravel(r0)])


class CoupledCMPC:
    """The joint NLP with the predictor inside, for a fixed problem size and predictor function.

    ``function`` is ``predictor.to_casadi(n_humans, n_robots, H)`` and ``context_size`` its context length.
    """

    def __init__(
        self, cfg: MPCConfig, n_robots: int, n_humans: int, function: ca.Function, context_size: int
    ):
        self.cfg, self.n_robots, self.n_humans = cfg, n_robots, n_humans
        self.function = function
        h = cfg.horizon
        self.n_out, self.n_in = 2 * h * n_humans, 2 * h * n_robots
        expanded = expand_if_small(function)
        self.mode = cfg.coupled_mode
        if self.mode == "auto":
            self.mode = "exact" if expanded is not None else "first_order"
        self.model: ExactPredictor | FirstOrderPredictor
        if self.mode == "exact":
            self.model = ExactPredictor(function, context_size, expanded)
        else:
            self.model = FirstOrderPredictor(self.n_out, self.n_in)
            # By position, not by name: the protocol fixes the inputs' order and sizes only.
            context = ca.MX.sym("context", function.size1_in(0))
            robots_future = ca.MX.sym("robots_future", function.size1_in(1))
            out = function(context, robots_future)
            self.jacobian_fn = ca.Function(
                "prediction_jacobian", [context, robots_future], [out, ca.jacobian(out, robots_future)]
            )
        self.nlp = JointNLP(cfg, n_robots, n_humans, humans_model=self.model)

    def build_all(self) -> None:
        """Build every solver instance a solve may call, not only those the first step needs."""
        self.nlp.build_all()

    def _predict(self, context: np.ndarray, positions: np.ndarray) -> np.ndarray | None:
        """``f(context, r)`` numerically for planned positions ``(M, H, 2)``; None when not finite."""
        robots_future = positions.transpose(1, 0, 2).ravel()
        flat = np.asarray(self.function(context, robots_future)).ravel()
        return finite_prediction(flat.reshape(self.cfg.horizon, self.n_humans, 2), self._pred_shape)

    @property
    def _pred_shape(self) -> tuple[int, int, int]:
        return (self.cfg.horizon, self.n_humans, 2)

    def solve(self, data: StepData, context: np.ndarray, start: Start) -> IBRResult:
        if self.mode == "exact":
            return self._solve_exact(data, np.asarray(context, dtype=float), start)
        return self._solve_first_order(data, np.asarray(context, dtype=float), start)

    def _result(self, data, accels, prediction, potentials, iterations, solves, solved, converged, status,
                predictions, lam_x, lam_g, solver_iterations) -> IBRResult:  # fmt: skip
        return joint_result(
            self.n_robots,
            self.cfg.horizon,
            accels=accels,
            positions=rollout_numpy(data.states, accels, self.cfg.dt)[0],
            prediction=prediction,
            potentials=potentials,
            iterations=iterations,
            solves=solves,
            solved=solved,
            converged=converged,
            status=status,
            predictions=predictions,
            lam_x=lam_x,
            lam_g=lam_g,
            solver_iterations=solver_iterations,
        )

    def _solve_exact(self, data: StepData, context: np.ndarray, start: Start) -> IBRResult:
        if not np.all(np.isfinite(context)):
            return self._result(data, start.accels, None, (), 1, 0, False, False, "nan_prediction", (),
                                None, None, 0)  # fmt: skip
        sol, solves, iterations = self.nlp.solve_multi_start(
            data, context, start.accels, start.lam_x, start.lam_g, **start.first_solve(1)
        )
        if not sol.success:
            return self._result(data, start.accels, None, (), 1, solves, False, False, sol.status, (),
                                None, None, iterations)  # fmt: skip
        prediction = self.nlp.humans(sol.accels, data, context)
        return self._result(data, sol.accels, prediction, (sol.cost,), 1, solves, True, True, "ok",
                            (prediction,), sol.lam_x, sol.lam_g, iterations)  # fmt: skip

    def _solve_first_order(self, data: StepData, context: np.ndarray, start: Start) -> IBRResult:
        cfg = self.cfg
        t0 = time.perf_counter()
        accels = start.accels
        positions = rollout_numpy(data.states, accels, cfg.dt)[0]
        lam_x = None if start.lam_x is None else start.lam_x.ravel()
        lam_g = None if start.lam_g is None else start.lam_g.ravel()
        status, solved, converged = "ok", False, False
        previous_potential, used, previous_model = math.inf, None, None
        predictions: list[np.ndarray] = []
        potentials: list[float] = []
        solves = solver_iterations = iterations = 0
        for j in range(1, cfg.j_max + 1):
            iterations = j
            r0 = positions.transpose(1, 0, 2).ravel()
            value, jac = self.jacobian_fn(context, r0)
            value, jac = np.asarray(value).ravel(), np.asarray(jac)
            if not (np.all(np.isfinite(value)) and np.all(np.isfinite(jac))):
                status = "nan_prediction"
                break
            predictions.append(value.reshape(self._pred_shape))
            model = (value - jac @ r0, jac)  # s_H = offset + J r: what the NLP sees
            if previous_model is not None and all(map(np.array_equal, model, previous_model)):
                converged = True  # the same NLP again (always so when J = 0): u^(j) = u^(j-1)
                potentials.append(potentials[-1])
                break
            previous_model = model
            extra = FirstOrderPredictor.params(value, jac, r0)
            sol, n_solves, n_iterations = self.nlp.solve_multi_start(
                data, extra, accels, lam_x, lam_g, **start.first_solve(j)
            )
            solves += n_solves
            solver_iterations += n_iterations
            if not sol.success:
                status = sol.status
                break
            new_positions = rollout_numpy(data.states, sol.accels, cfg.dt)[0]
            prediction = self._predict(context, new_positions)
            if prediction is None:
                status = "nan_prediction"
                break
            accels, positions, lam_x, lam_g = sol.accels, new_positions, sol.lam_x, sol.lam_g
            solved, used = True, prediction
            # F with the true predictor at the new plan: s_H = f(r(u)) equals the model's value at r0 = r(u).
            exact = FirstOrderPredictor.params(prediction, jac, positions.transpose(1, 0, 2).ravel())
            potential = self.nlp.potential(accels, data, exact)
            potentials.append(potential)
            if abs(potential - previous_potential) <= cfg.xi:
                converged = True
                break
            if time.perf_counter() - t0 > cfg.time_limit_s:
                status = "timeout"
                break
            previous_potential = potential
        return self._result(data, accels, used, potentials, iterations, solves, solved, converged, status,
                            predictions, lam_x, lam_g, solver_iterations)  # fmt: skip
