"""Conformal calibration of a predictor's displacement errors (Lindemann et al. 2023, "Safe planning in
dynamic environments using conformal prediction").

The MPC enlarges its robot-human safety distance at horizon step ``k`` (1..H) by a margin ``m_k``, the
``(1 - alpha)`` split-conformal quantile of the predictor's step-``k`` displacement error on calibration data.
The statistics (quantiles with the finite-sample correction, coverage, what the guarantee is) are in
``predictors.conformal``, the errors on real (TrajNet++) scenes in ``predictors.real_data``; this module turns
them into blocks (``predictors.calibration_store`` stores them and finds the block a controller asks for).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final

import numpy as np

from crowdsim.world import is_sensor_range, sensor_range_refused
from predictors.base import DT, Predictor
from predictors.conformal import MIN_ALPHA, alpha_text, check_alpha, min_samples, step_counts, step_quantiles
from predictors.conformal_classes import ClassMargins, class_margins
from predictors.errors import PredictorError
from predictors.hashing import is_sha256
from predictors.real_data import HORIZON, combined_sha256, file_hashes, real_errors

SOURCES: Final[tuple[str, ...]] = ("real", "closed-loop")
# alphas closer than this are one calibration key: the smallest alpha accepted (conformal.MIN_ALPHA says why)
ALPHA_TOLERANCE: Final[float] = MIN_ALPHA


def same_alpha(a: float, b: float) -> bool:
    """Whether ``a`` and ``b`` name one calibration key (within ``ALPHA_TOLERANCE``)."""
    return abs(a - b) <= ALPHA_TOLERANCE


def now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _is_count(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _is_margin(value: object) -> bool:
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        return False
    return math.isfinite(value) and value >= 0


@dataclass(frozen=True)
class Calibration:
    """The conformal margins of one predictor for one data source and alpha."""

    predictor: str  # registry / zoo name
    predictor_sha256: str | None  # the zoo weights' sha256; None for weightless ones (constant_velocity)
    source: str  # "real" (TrajNet++ data) or "closed-loop" (simulated episodes)
    alpha: float  # miscoverage: margins cover with probability >= 1 - alpha (module doc)
    n: tuple[int, ...]  # calibration samples per horizon step k = 1..H
    quantiles: tuple[float, ...]  # margins m_k in metres, per step k = 1..H
    data_sha256: str  # identifies the calibration data (files, or episodes and their settings)
    details: dict[str, Any] = field(default_factory=dict)  # free JSON: files, seeds, settings
    created: str = field(default_factory=now_iso)  # ISO 8601 time of calibration
    # margins per motion class and step (predictors.conformal_classes); None where the data has no classes
    # (real scenes) or too few samples in a class for alpha
    classes: ClassMargins | None = None
    # the same per class for the distance-shortfall score (closed-loop only: how much closer a human came to
    # a robot than predicted, pipelines/experiments/calibrate.py), the margins of conformal-shortfall
    shortfall: ClassMargins | None = None

    def __post_init__(self):
        if not isinstance(self.predictor, str) or not self.predictor:
            raise PredictorError(f"calibration 'predictor' must be a non-empty name, got {self.predictor!r}")
        if self.predictor_sha256 is not None and not is_sha256(self.predictor_sha256):
            raise PredictorError(
                f"calibration 'predictor_sha256' must be 64 lowercase hex digits or null, "
                f"got {self.predictor_sha256!r}"
            )
        if self.source not in SOURCES:
            raise PredictorError(f"calibration 'source' must be one of {list(SOURCES)}, got {self.source!r}")
        check_alpha(self.alpha, "calibration 'alpha'")
        self._check_steps()
        if not is_sha256(self.data_sha256):
            raise PredictorError(
                f"calibration 'data_sha256' must be 64 lowercase hex digits, got {self.data_sha256!r}"
            )
        self._check_details_and_time()
        for extra in (self.classes, self.shortfall):
            if extra is not None and extra.horizon != len(self.quantiles):
                raise PredictorError(
                    f"calibration class margins cover {extra.horizon} steps, its quantiles "
                    f"{len(self.quantiles)}"
                )

    def _check_steps(self) -> None:
        if not isinstance(self.n, tuple) or not self.n or not all(_is_count(c) for c in self.n):
            raise PredictorError(f"calibration 'n' must be a non-empty list of sample counts, got {self.n!r}")
        if not isinstance(self.quantiles, tuple) or not all(_is_margin(q) for q in self.quantiles):
            raise PredictorError(
                f"calibration 'quantiles' must be a list of finite non-negative metres, "
                f"got {self.quantiles!r}"
            )
        need = min_samples(self.alpha)  # fewer give no finite quantile: calibrate stores no such block
        if min(self.n) < need:
            raise PredictorError(
                f"calibration 'n' {list(self.n)}: a finite quantile at alpha={alpha_text(self.alpha)} takes "
                f"at least {need} samples a step"
            )
        if len(self.quantiles) != len(self.n):
            raise PredictorError(
                f"calibration has {len(self.quantiles)} quantiles but {len(self.n)} sample counts; "
                "expected one of each per horizon step"
            )

    def _check_details_and_time(self) -> None:
        if not isinstance(self.details, dict):
            raise PredictorError(f"calibration 'details' must be a JSON object, got {self.details!r}")
        made = self.details.get("sensor_range")
        if made is not None and not is_sensor_range(made):
            raise PredictorError(
                f"calibration 'details.sensor_range' must be a finite number of metres > 0 (or absent: every "
                f"human in view), got {made!r}"
            )
        if made is not None and self.source != "closed-loop":  # real scenes were recorded, not sensed
            raise PredictorError(
                f"calibration 'details.sensor_range' is for closed-loop blocks, this one is {self.source!r}"
            )
        tracks = self.details.get("sensor_tracks", True)
        if not isinstance(tracks, bool) or (tracks is False and made is None):
            raise PredictorError(
                "calibration 'details.sensor_tracks' must be true or false, and false only beside a "
                f"sensor_range (track lengths are a sensor's), got {tracks!r}"
            )
        try:
            json.dumps(self.details, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise PredictorError(f"calibration 'details' is not plain JSON ({exc})") from None
        try:
            datetime.fromisoformat(self.created)
        except (TypeError, ValueError):
            raise PredictorError(
                f"calibration 'created' must be an ISO 8601 time, got {self.created!r}"
            ) from None

    @property
    def horizon(self) -> int:
        return len(self.quantiles)

    @property
    def sensor_range(self) -> float | None:
        """The range in metres of the sensor a closed-loop calibration's robots were behind (``calibrate
        --sensor-range``), None where they saw every human (and for real scenes)."""
        made = self.details.get("sensor_range")
        return None if made is None else float(made)

    @property
    def sensor_tracks(self) -> bool:
        """Whether the tracker of the sensor the robots were behind reported its track lengths
        (``calibrate --no-sensor-tracks``: not); True for a block made with every human in view."""
        return self.details.get("sensor_tracks", True) is not False

    def key(self) -> tuple[str, str, float, float | None, bool]:
        """What one block is stored per: blocks made behind different sensors (with or without the track
        lengths), or with every human in view, stand side by side, and a controller plans with the one made
        behind its own sensor."""
        return self.predictor, self.source, self.alpha, self.sensor_range, self.sensor_tracks

    def matches(self, predictor: str, source: str, alpha: float) -> bool:
        """Whether this block is of ``predictor``, ``source`` and ``alpha``, behind whatever sensor."""
        return self.predictor == predictor and self.source == source and same_alpha(self.alpha, alpha)

    def same_key(self, other: Calibration) -> bool:
        """Whether ``other`` is stored in this block's place (``key``; alphas within ``ALPHA_TOLERANCE``)."""
        return self.matches(other.predictor, other.source, other.alpha) and self.key()[3:] == other.key()[3:]

    def to_json(self) -> dict:
        classes = {} if self.classes is None else {"classes": self.classes.to_json()}
        if self.shortfall is not None:
            classes["shortfall"] = self.shortfall.to_json()
        return {
            "predictor": self.predictor,
            "predictor_sha256": self.predictor_sha256,
            "source": self.source,
            "alpha": self.alpha,
            "n": list(self.n),
            "quantiles": list(self.quantiles),
            "data_sha256": self.data_sha256,
            "details": self.details,
            "created": self.created,
        } | classes

    @classmethod
    def from_json(cls, values: object, where: str | Path) -> Calibration:
        if not isinstance(values, dict):
            raise PredictorError(f"{where}: a calibration must be a JSON object, got {values!r}")
        required = ("predictor", "predictor_sha256", "source", "alpha", "n", "quantiles", "data_sha256")
        missing = [k for k in (*required, "created") if k not in values]
        if missing:
            raise PredictorError(f"{where}: calibration {values.get('predictor', '?')!r} lacks {missing}")
        lists = {k: values[k] for k in ("n", "quantiles")}
        bad = [k for k, v in lists.items() if not isinstance(v, list)]
        if bad:
            raise PredictorError(f"{where}: calibration {bad} must be lists (one entry per horizon step)")
        try:
            return cls(
                **{k: values[k] for k in required if k not in lists},
                n=tuple(lists["n"]),
                quantiles=tuple(lists["quantiles"]),
                details=values.get("details", {}),
                created=values["created"],
                classes=None if values.get("classes") is None else ClassMargins.from_json(values["classes"]),
                shortfall=(
                    None if values.get("shortfall") is None else ClassMargins.from_json(values["shortfall"])
                ),
            )
        except PredictorError as exc:
            raise PredictorError(f"{where}: {exc}") from None


def beyond_remaking(block: Calibration) -> str:
    """Empty where a refusal about ``block`` may quote the command of its own view to make it again, else why
    not: a block made behind a sensor range beyond crowdsim.world.SENSOR_RANGE (stored before that bound; it
    stays usable) is one calibrate refuses now, so the refusal quotes the command of the view asked for, whose
    block is planned with before it (calibration_store.view_distance: the same view first)."""
    made = block.sensor_range
    refused = None if made is None else sensor_range_refused(made)
    if refused is None:
        return ""
    return (
        f"; the block was made behind a {made:g} m sensor before calibrate bounded the range ({refused}) and "
        "cannot be made again: the command makes one of the view asked for, planned with before it"
    )


def remaking_view(
    block: Calibration, wanted: tuple[float | None, bool]
) -> tuple[tuple[float | None, bool], str]:
    """The view (sensor range, track lengths given) of the command a note or refusal quotes to make ``block``
    again, and ``beyond_remaking``'s why ("" where the block's own view's command makes it again): the
    block's own, or ``wanted`` (the run's) where calibrate refuses the block's range, as the notes quoted
    ``--sensor-range 2000`` for a block made before the bound."""
    why = beyond_remaking(block)
    return (wanted if why else (block.sensor_range, block.sensor_tracks)), why


def calibration_from_errors(
    errors: np.ndarray,
    *,
    predictor: str,
    predictor_sha256: str | None,
    source: str,
    alpha: float,
    data_sha256: str,
    details: dict | None = None,
    classes: np.ndarray | None = None,
    shortfall: np.ndarray | None = None,
) -> Calibration:
    """The block for ``errors`` (module layout); refuses a step with too few samples for ``alpha``.
    ``classes``: the motion class of each error row, for class margins as well (``conformal_classes``);
    with ``shortfall`` (the rows' distance shortfalls, same layout as ``errors``), its class margins too."""
    quantiles = step_quantiles(errors, alpha)
    counts = step_counts(errors)
    short = [k + 1 for k, q in enumerate(quantiles) if not math.isfinite(q)]
    if short:
        raise PredictorError(
            f"too few {source} samples for alpha={alpha_text(alpha)} at horizon step(s) {short} "
            f"(samples per step {list(counts)}, need at least {min_samples(alpha)}); use more data or a "
            "larger alpha"
        )
    return Calibration(
        predictor=predictor,
        predictor_sha256=predictor_sha256,
        source=source,
        alpha=float(alpha),
        n=counts,
        quantiles=quantiles,
        data_sha256=data_sha256,
        details=dict(details or {}),
        created=now_iso(),
        classes=None if classes is None else class_margins(errors, classes, alpha),
        shortfall=None if classes is None or shortfall is None else class_margins(shortfall, classes, alpha),
    )


def calibrations_from_errors(errors: np.ndarray, alphas: Sequence[float], **block: Any) -> list[Calibration]:
    """One block per alpha from the same errors; ``block``: calibration_from_errors' keywords but alpha."""
    return [calibration_from_errors(errors, alpha=alpha, **block) for alpha in alphas]


# ---------------------------------------------------------------------------------------------- real data
def calibrate_real(
    predictor: Predictor,
    files: list[Path],
    alphas: list[float] | tuple[float, ...],
    horizon: int = HORIZON,
    root: str | Path | None = None,
    sha256: str | None = None,
) -> tuple[list[Calibration], np.ndarray]:
    """One "real" block per alpha from ``files`` (``sha256``: the predictor's weights), and the errors."""
    if not alphas:
        raise PredictorError("need at least one alpha to calibrate")
    if not files:
        raise PredictorError("need at least one ndjson file to calibrate on")
    hashes = file_hashes(files, root)
    errors = real_errors(predictor, files, horizon)
    details = {
        "files": hashes,
        "obs_len": predictor.obs_len,
        "horizon": horizon,
        "dt": DT,
        "rows": int(errors.shape[0]),
    }
    blocks = calibrations_from_errors(
        errors,
        alphas,
        predictor=predictor.name,
        predictor_sha256=sha256,
        source="real",
        data_sha256=combined_sha256(hashes),
        details=details,
    )
    return blocks, errors
