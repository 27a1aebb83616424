"""Synthetic calibration data whose conformal quantiles are known by hand, shared by the margin tests."""

import numpy as np

from predictors.calibration import Calibration, calibration_from_errors
from predictors.conformal_classes import MOTION_CLASSES


def class_errors(horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """19 samples per motion class; class c's step-k error is i/100 * (c + 1) * k, i = 1..19, so its
    0.9 conformal quantile (the 18th smallest of 19) is 0.18 (c + 1) k."""
    base = np.arange(1, 20) / 100.0
    steps = np.arange(1.0, horizon + 1)
    errors = np.concatenate([np.outer(base * (c + 1), steps) for c in range(len(MOTION_CLASSES))])
    return errors, np.repeat(np.arange(len(MOTION_CLASSES)), 19)


def constant_velocity_block(errors: np.ndarray, **extra) -> Calibration:
    """constant_velocity's closed-loop block at alpha 0.1 for ``errors`` (``extra``: classes, shortfall)."""
    return calibration_from_errors(
        errors,
        predictor="constant_velocity",
        predictor_sha256=None,
        source="closed-loop",
        alpha=0.1,
        data_sha256="0" * 64,
        **extra,
    )


def synthetic_closed_loop(plan, errors: np.ndarray | None = None):
    """What calibrate's closed-loop episodes (``pipelines.experiments.calibrate.closed_loop_errors``) return
    for ``plan``, made up: ``class_errors(4)`` (19 per motion class, shortfall = error) or ``errors``."""
    from pipelines.experiments.calibrate import ClosedLoopErrors

    scores, motion = class_errors(4) if errors is None else (errors, np.zeros(len(errors), dtype=int))
    return ClosedLoopErrors(scores, motion, scores, {"seeds": [plan.seed, plan.seed]}, None)
