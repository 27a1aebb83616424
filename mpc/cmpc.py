"""Algorithm 1, IBR-based centralized MPC: alternate the humans' prediction and the joint solve (Eq. 17).

At iteration ``j`` the predictor is rolled out given the robots' planned positions of iteration ``j-1``
(the recursive, coupled prediction of Eq. 1), then the joint NLP is solved with those predictions,
warm-started from iteration ``j-1``. The loop stops when ``|F^(j) - F^(j-1)| <= xi`` (``F^(0) = inf``, so
at least two predictions are made) or at ``j_max``.

A prediction identical (bit for bit) to the previous one means the NLP to solve is the one just solved: its
solution is ``u^(j-1)`` and ``F^(j) = F^(j-1)``, so the solve is skipped and the loop ends converged. This is
a fixed point of Algorithm 1, not an approximation; it is what happens at every step with a predictor that
ignores the robots (constant velocity).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mpc.config import MPCConfig
from mpc.dynamics import rollout_numpy
from mpc.fallback import Start
from mpc.nlp import JointNLP, StepData
from mpc.step_data import MAX_MAGNITUDE

# predict(robots_future (H, M, 2)) -> humans' predicted positions (H, N_h, 2)
PredictFn = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class IBRResult:
    """The outcome of one control step's IBR loop (Algorithm 1 or 2)."""

    accels: np.ndarray  # (M, H, 2) the plan to apply (the fallback Start.accels when nothing was solved)
    positions: np.ndarray  # (M, H, 2) its planned positions at t+1..t+H
    prediction: np.ndarray | None  # (H, N_h, 2) the prediction the plan was optimised against
    potential: float  # F_t (Eq. 16) of the plan under ``prediction`` (nan when nothing was solved)
    iterations: int  # IBR iterations j used
    solves: int  # NLP solves run (CMPC: one per iteration, two when it restarts from braking; DMPC: up to
    # M per iteration, then its pair and conflict moves)
    solved: bool  # at least one solve produced the plan (False: ``accels`` is the fallback Start.accels)
    converged: bool  # the stopping test of the algorithm held before j_max
    # "ok", or the first failure: a solver status (mpc/solvers.py), "nan_prediction", "timeout"; DMPC reports
    # "ok" where any robot's solve gave the plan, its first failure only when none did
    status: str
    predictions: tuple[np.ndarray, ...]  # (H, N_h, 2) of every iteration
    # F^(j) of every iteration after the first plan (one whose prediction repeated, or whose DMPC solves all
    # failed, repeats the last), then DMPC's pair moves'
    potentials: tuple[float, ...]
    lam_x: np.ndarray | None  # (M, H, 2) multipliers of the final plan, for the next warm start
    lam_g: np.ndarray | None
    solver_iterations: int  # solver iterations summed over the solves


def joint_result(
    n_robots: int,
    horizon: int,
    *,
    accels: np.ndarray,
    positions: np.ndarray,
    prediction: np.ndarray | None,
    potentials: list[float] | tuple[float, ...],
    iterations: int,
    solves: int,
    solved: bool,
    converged: bool,
    status: str,
    predictions: list[np.ndarray] | tuple[np.ndarray, ...],
    lam_x: np.ndarray | None,
    lam_g: np.ndarray | None,
    solver_iterations: int,
) -> IBRResult:
    """The result of a joint-NLP loop (CMPC, coupled NLP): F of the last iteration, and multipliers shaped
    ``(M, H, 2)`` only when a plan was solved (a failed step warm-starts nothing)."""
    shape = (n_robots, horizon, 2)
    return IBRResult(
        accels=accels,
        positions=positions,
        prediction=prediction,
        potential=potentials[-1] if potentials else math.nan,
        iterations=iterations,
        solves=solves,
        solved=solved,
        converged=converged,
        status=status,
        predictions=tuple(predictions),
        potentials=tuple(potentials),
        lam_x=None if lam_x is None or not solved else np.reshape(lam_x, shape),
        lam_g=None if lam_g is None or not solved else np.reshape(lam_g, shape),
        solver_iterations=solver_iterations,
    )


def finite_prediction(prediction: np.ndarray, shape: tuple[int, ...]) -> np.ndarray | None:
    """``prediction`` as float64 when it is finite and within ``MAX_MAGNITUDE`` everywhere, None where it is
    not (the step reports ``nan_prediction`` and falls back: a human predicted at -1e308 made the NLP's
    gradient NaN, and a Fatrop solve never returned); a ValueError when it is not of ``shape``
    ``(H, N_h, 2)``: a predict function of one's own returning ``(N_h, H, 2)`` was reported as a NaN
    prediction, and its every step fell back without a word of shapes."""
    prediction = np.asarray(prediction, dtype=float)
    if prediction.shape != shape:
        raise ValueError(
            f"the predict function returned shape {prediction.shape}, expected {shape}: (H, N_h, 2), the "
            "horizon's steps, then the humans, in metres"
        )
    if not np.all(np.abs(prediction) <= MAX_MAGNITUDE):  # NaN too
        return None
    return prediction


class CMPC:
    """Algorithm 1 for a fixed problem size; the joint NLP is built once, here."""

    def __init__(self, cfg: MPCConfig, n_robots: int, n_humans: int):
        self.cfg, self.n_robots, self.n_humans = cfg, n_robots, n_humans
        self.nlp = JointNLP(cfg, n_robots, n_humans)

    def build_all(self) -> None:
        """Build every solver instance a solve may call, not only those the first step needs."""
        self.nlp.build_all()

    def solve(self, data: StepData, predict: PredictFn, start: Start) -> IBRResult:
        cfg = self.cfg
        t0 = time.perf_counter()
        pred_shape = (cfg.horizon, self.n_humans, 2)
        accels = start.accels
        positions = rollout_numpy(data.states, accels, cfg.dt)[0]
        lam_x = None if start.lam_x is None else start.lam_x.ravel()
        lam_g = None if start.lam_g is None else start.lam_g.ravel()
        status, solved, converged = "ok", False, False
        potential, previous_potential = math.nan, math.inf
        used, previous, predictions, potentials = None, None, [], []
        solves = solver_iterations = iterations = 0
        for j in range(1, cfg.j_max + 1):
            iterations = j
            prediction = finite_prediction(predict(positions.transpose(1, 0, 2)), pred_shape)
            if prediction is None:
                status = "nan_prediction"
                break
            predictions.append(prediction)
            if previous is not None and np.array_equal(prediction, previous):
                converged = True  # the same NLP again: u^(j) = u^(j-1), F^(j) = F^(j-1)
                potentials.append(potential)
                break
            sol, n_solves, n_iterations = self.nlp.solve_multi_start(
                data, prediction, accels, lam_x, lam_g, **start.first_solve(j)
            )
            solves += n_solves
            solver_iterations += n_iterations
            if not sol.success:
                # Algorithm 1 says nothing of it: a failure after the first solve keeps u^(j-1), a solve's
                # plan against the previous prediction (no fallback), the step's status naming the failure
                status = sol.status
                break
            accels, lam_x, lam_g, potential = sol.accels, sol.lam_x, sol.lam_g, sol.cost
            positions = rollout_numpy(data.states, accels, cfg.dt)[0]
            solved, used = True, prediction
            potentials.append(potential)
            if abs(potential - previous_potential) <= cfg.xi:
                converged = True
                break
            if time.perf_counter() - t0 > cfg.time_limit_s:
                status = "timeout"
                break
            previous_potential, previous = potential, prediction
        return joint_result(
            self.n_robots,
            cfg.horizon,
            accels=accels,
            positions=positions,
            prediction=used,
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
