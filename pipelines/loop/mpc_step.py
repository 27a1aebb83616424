"""Pieces of one MPC control step that read no controller state (pipelines.loop.mpc's ``MPCController.act``
keeps the state: its plan memory, stall watch and counters): the crowd allowances of the step's
``StepData``, and the ``ControlOutput`` of a solve or of a solve that raised."""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from crowdsim.control import ControlOutput
from mpc.dynamics import rollout_numpy
from mpc.guidance import guidance_targets, lookahead
from pipelines.loop.motion_classes import observed_classes
from pipelines.loop.step_record import allowances_record
from predictors.conformal_classes import MOTION_CLASSES

if TYPE_CHECKING:
    from crowdsim.observation import Observation
    from mpc.cmpc import IBRResult
    from mpc.config import MPCConfig
    from mpc.nlp import StepData
    from predictors.conformal_classes import ClassMargins

STANDING = MOTION_CLASSES.index("standing")


def crowd_allowances(
    cfg: MPCConfig,
    class_margins: ClassMargins | None,
    obs: Observation,
    states: np.ndarray,
    on_goal: np.ndarray,
) -> dict[str, Any]:
    """StepData's ``human_margins`` (per-class margins: each human's, ``(H, N_h)``) and ``targets``
    (guidance "standing": around the humans standing still); absent: the configured margins for every
    human, the goals."""
    if class_margins is None and cfg.guidance == "none":
        return {}
    classes = observed_classes(obs)
    out: dict[str, Any] = {}
    if class_margins is not None:
        out["human_margins"] = margins = class_margins.per_human(classes, cfg.horizon)
    if cfg.guidance == "standing":
        standing = classes == STANDING
        last = cfg.horizon - 1
        margin = (
            margins[last, standing].max(initial=0.0) if "human_margins" in out else cfg.human_margin(last)
        )
        out["targets"] = guidance_targets(
            states[:, :2],
            obs.robot_goals,
            obs.human_positions[standing],
            cfg.standing_clearance(float(margin)),
            ~on_goal,
            lookahead(cfg.v_max, cfg.horizon, cfg.dt),
        )
    return out


def raised_output(
    exc: Exception, accels: np.ndarray, kind: str, data: StepData, t0: float, dt: float, solve_exceptions: int
) -> ControlOutput:
    """A solve that raised: the step falls back to its start ``accels`` (``Start.accels``, of ``kind``) as
    for any failed solve, and says what was raised; ``solve_exceptions`` counts them in this episode."""
    return ControlOutput(
        accelerations=accels[:, 0].copy(),
        solve_time_s=time.perf_counter() - t0,
        status=f"exception: {type(exc).__name__}",
        fallback=kind,
        plan=rollout_numpy(data.states, accels, dt)[0],
        extra={
            "exception": f"{type(exc).__name__}: {exc}"[:500],
            "solve_exceptions": solve_exceptions,
        },
    )


def solve_output(
    result: IBRResult, fallback: str | None, data: StepData, t0: float, dt: float, record_iterations: bool
) -> ControlOutput:
    """The step's output from the IBR loop's ``result``: its plan (the start, when unsolved: ``fallback``
    names it), solver facts, and the iterations' predictions where ``record_iterations``."""
    plan = result.accels
    return ControlOutput(
        accelerations=plan[:, 0].copy(),
        solve_time_s=time.perf_counter() - t0,
        status=result.status,
        iterations=result.iterations,
        fallback=fallback,
        potential=result.potential if math.isfinite(result.potential) else None,
        plan=rollout_numpy(data.states, plan, dt)[0],
        prediction=result.prediction,
        iteration_predictions=result.predictions if record_iterations else (),
        extra={
            "solves": result.solves,
            "solver_iterations": result.solver_iterations,
            "converged": result.converged,
            **allowances_record(data),
        },
    )
