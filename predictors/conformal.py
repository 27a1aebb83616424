"""Split-conformal statistics of a predictor's step-wise displacement errors (Lindemann et al. 2023).

Error layout (used everywhere, also by the closed-loop source): ``errors`` is a float array ``(n, H)``; a row
is one (human, prediction time) sample and column ``k-1`` is ``|predicted - realised|`` at step ``k`` in
metres, NaN where the realised position at step ``k`` is unknown (the episode or scene ended). Each column is
calibrated on its own non-NaN entries. ``predictors.calibration`` makes margin blocks of the quantiles
(``predictors.calibration_store`` stores them).

What the guarantee is, honestly: for *exchangeable* calibration and test samples, split conformal gives
marginal coverage ``P(error_k <= m_k) >= 1 - alpha`` for each step ``k`` separately (not jointly over the
steps). Samples from the same scene or episode are correlated (neighbouring humans, overlapping time windows),
and closed-loop errors depend on the planner that used the margins, so exchangeability is at best
approximate: the coverage measured on held-out data (``coverage``) is what to report, not ``1 - alpha``.
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import Final

import numpy as np

from predictors.errors import PredictorError

# The smallest alpha accepted: its finite-sample quantile needs 1/alpha - 1 samples (10^12 here, more than any
# calibration will have), and alphas closer than 1e-12 are one calibration key (predictors.calibration), so a
# smaller one could not be told apart from its neighbours, nor from 0.
MIN_ALPHA: Final[float] = 1e-12


def check_alpha(alpha: float, what: str = "alpha") -> float:
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)) or not 0.0 < alpha < 1.0:
        raise PredictorError(f"{what} must be a number with 0 < alpha < 1, got {alpha!r}")
    if alpha < MIN_ALPHA:
        raise PredictorError(
            f"{what} must be at least {MIN_ALPHA:g} (a finite margin at {alpha!r} needs more than "
            f"{1 / MIN_ALPHA:.0e} samples), got {alpha!r}"
        )
    return float(alpha)


def alpha_text(alpha: float) -> str:
    """``alpha`` exactly, as its shortest decimal (``repr``): messages and the commands they advise name the
    very calibration key, where ``:g`` keeps 6 digits and would print 0.1234567 as 0.123457, another key."""
    return repr(float(alpha))


def _exact(alpha: float) -> Fraction:
    """``alpha`` as the decimal it prints as (its shortest repr: what the user wrote, 0.1 and not the binary
    float 0.1000000000000000055...), exactly: (n + 1)(1 - alpha) then lands on an integer exactly when it
    does in decimal, with no slack that would misplace the rank of alphas written with many digits."""
    return Fraction(alpha_text(check_alpha(alpha)))


def conformal_rank(n: int, alpha: float) -> int:
    """The 1-based rank ``ceil((n + 1)(1 - alpha))`` of the split-conformal quantile among ``n`` scores (at
    least 1: 0 < alpha < 1)."""
    return math.ceil((n + 1) * (1 - _exact(alpha)))


def min_samples(alpha: float) -> int:
    """The fewest scores for which the quantile at ``alpha`` is finite, ``ceil(1/alpha - 1)``: the least
    ``n`` with ``conformal_rank(n, alpha) <= n`` (at least 1)."""
    return math.ceil(1 / _exact(alpha) - 1)


def conformal_quantile(scores: np.ndarray, alpha: float) -> float:
    """Split-conformal ``(1 - alpha)`` quantile of 1-D finite non-negative ``scores``.

    Sorts the ``n`` scores and returns the ``ceil((n + 1)(1 - alpha))``-th smallest (the finite-sample
    correction). When that rank exceeds ``n`` there are too few samples for this alpha (fewer than
    ``min_samples(alpha)``, e.g. 9 at alpha = 0.1) and the honest answer is ``math.inf``: no finite margin is
    guaranteed to cover.
    """
    scores = np.asarray(scores, dtype=float)
    if scores.ndim != 1:
        raise PredictorError(f"scores must be a 1-D array, got shape {scores.shape}")
    if not np.all(np.isfinite(scores)) or np.any(scores < 0):
        bad = scores[~(np.isfinite(scores) & (scores >= 0))][0]
        raise PredictorError(f"scores must be finite and non-negative (errors in metres), got {bad!r}")
    rank = conformal_rank(len(scores), alpha)
    if rank > len(scores):
        return math.inf
    return float(np.partition(scores, rank - 1)[rank - 1])


def _check_errors(errors: np.ndarray) -> np.ndarray:
    errors = np.asarray(errors, dtype=float)
    if errors.ndim != 2 or errors.shape[1] < 1:
        raise PredictorError(f"errors must have shape (n, H) with H >= 1, got {errors.shape}")
    known = errors[~np.isnan(errors)]
    bad = known[~(np.isfinite(known) & (known >= 0))]
    if bad.size:
        raise PredictorError(
            f"errors must be finite non-negative distances in metres (NaN where unknown), got {bad[0]!r}"
        )
    return errors


def step_counts(errors: np.ndarray) -> tuple[int, ...]:
    """Non-NaN samples per horizon step (column)."""
    errors = _check_errors(errors)
    return tuple(int(c) for c in (~np.isnan(errors)).sum(axis=0))


def step_quantiles(errors: np.ndarray, alpha: float) -> tuple[float, ...]:
    """``conformal_quantile`` of each column's non-NaN entries (``inf`` where a column has too few)."""
    errors = _check_errors(errors)
    return tuple(conformal_quantile(col[~np.isnan(col)], alpha) for col in errors.T)


# Errors within a nanometre of a margin count as covered: constant velocity's errors on people walking
# straight are 0 up to rounding (1e-16 m), and its margins at alpha 0.5 too (2.5e-16 m), which an exact
# comparison ranked as misses or hits by rounding alone (a step's held-out coverage 35.5 %, where 41.3 % of
# the errors are within 1e-9 m of it).
COVERAGE_TOLERANCE: Final[float] = 1e-9  # m


def coverage(errors: np.ndarray, quantiles: tuple[float, ...] | list[float]) -> tuple[float, ...]:
    """Share (0..1) of each column's non-NaN entries with error <= its quantile (within
    ``COVERAGE_TOLERANCE``); NaN for an empty column."""
    errors = _check_errors(errors)
    quantiles = tuple(float(q) for q in quantiles)
    if len(quantiles) != errors.shape[1]:
        raise PredictorError(f"{len(quantiles)} quantiles for errors of {errors.shape[1]} horizon steps")
    shares = []
    for col, q in zip(errors.T, quantiles, strict=True):
        known = col[~np.isnan(col)]
        shares.append(float(np.mean(known <= q + COVERAGE_TOLERANCE)) if known.size else math.nan)
    return tuple(shares)


# -------------------------------------------------------------------------------------------- the block
