"""Class-conditional (Mondrian) conformal margins: one quantile per horizon step *and* motion class.

Why. One margin per step for every human (``predictors.conformal``) is the quantile of a mixture: humans
walking at their preferred speed, humans who have just appeared, humans standing still at their goals. In
closed-loop calibration of ``social_lstm_eth`` (CMPC, 60 episodes, 5-9 humans, alpha 0.1) the pooled step-4
margin is 0.65 m, but a human who has stood still over the whole observed window moves less than 0.18 m in
90 % of cases, while one observed for fewer than L steps moves 0.97 m. With the pooled margin a human standing
1.4 m from a robot's goal keeps the robot from reaching it (d_min + 0.65 m > 1.4 m), and the episode times
out: most of what margins cost in success is such standing humans. Calibrating each class on its own gives
each human the margin of the humans it moves like.

The classes are a function of what the controller observes (the humans' observed positions), fixed before
calibration, so Vovk's Mondrian conformal prediction applies: for exchangeable samples, each class ``c`` and
step ``k`` has ``P(error_k <= m_ck | class c) >= 1 - alpha``, coverage *within every class*, which is stronger
than the pooled guarantee (the caveats of ``predictors.conformal`` on exchangeability stand).

``MOTION_CLASSES`` (index: name): 0 ``new``, observed for fewer than L positions (its window is not full, so
its speed is unknown); otherwise by the net speed over the observed window, ``|x_t - x_{t-L+1}| / ((L-1)
tau)``: 1 ``standing`` below ``STANDING_SPEED``, 2 ``slow`` below ``WALKING_SPEED``, 3 ``walking``. In the
closed loop (``pipelines.loop.motion_classes.observed_classes``) L is ``CLASS_WINDOW``, the window closed-loop
calibration classifies with, whatever history the simulator keeps: a margin is calibrated for one classifier.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np

from crowdsim.world import OBS_LEN
from predictors.conformal import coverage, min_samples, step_counts, step_quantiles
from predictors.errors import PredictorError

MOTION_CLASSES: Final[tuple[str, ...]] = ("new", "standing", "slow", "walking")
STANDING_SPEED: Final[float] = 0.1  # m/s over the observed window: below it, a human "stands"
WALKING_SPEED: Final[float] = 0.6  # m/s: at or above it, a human "walks" (ORCA's preferred speed is 1 m/s)
# L of the closed loop's classes: closed-loop calibration runs the default world, whose history holds OBS_LEN
# rows, so a simulator keeping more rows ([world] obs_len) must not lengthen the window the classes read
CLASS_WINDOW: Final[int] = OBS_LEN


def motion_classes(history: np.ndarray, observed: int | np.ndarray, dt: float) -> np.ndarray:
    """The ``MOTION_CLASSES`` index ``(N,)`` of each human from its last ``L`` observed positions.

    ``history``: ``(L, N, 2)``, row -1 the current position; ``observed``: how many positions of each human
    have really been observed (scalar or ``(N,)``; rows before those are padding).
    """
    history = np.asarray(history, dtype=float)
    if history.ndim != 3 or history.shape[0] < 2 or history.shape[2] != 2:
        raise PredictorError(f"history must have shape (L >= 2, N, 2), got {history.shape}")
    window = history.shape[0]
    speed = np.linalg.norm(history[-1] - history[0], axis=-1) / ((window - 1) * dt)
    classes = np.where(speed < STANDING_SPEED, 1, np.where(speed < WALKING_SPEED, 2, 3))
    new = np.broadcast_to(np.asarray(observed), classes.shape) < window
    return np.where(new, 0, classes).astype(np.int64)


@dataclass(frozen=True)
class ClassMargins:
    """Margins ``m_ck`` per motion class ``c`` (``MOTION_CLASSES`` order) and horizon step ``k``."""

    n: tuple[tuple[int, ...], ...]  # calibration samples per class and step
    quantiles: tuple[tuple[float, ...], ...]  # metres per class and step
    standing_speed: float = STANDING_SPEED  # m/s, the class edges they were calibrated with
    walking_speed: float = WALKING_SPEED

    def __post_init__(self):
        names = len(MOTION_CLASSES)
        n, q = self.n, self.quantiles
        if len(n) != names or len(q) != names:
            raise PredictorError(f"class margins need one row per class {list(MOTION_CLASSES)}, got {len(q)}")
        horizon = len(q[0])
        for counts, row in zip(n, q, strict=True):
            if len(row) != horizon or len(counts) != horizon or not horizon:
                raise PredictorError("class margins need the same number (>= 1) of steps in every class")
            if not all(isinstance(c, int) and not isinstance(c, bool) and c >= 0 for c in counts):
                raise PredictorError(f"class margin sample counts must be integers >= 0, got {list(counts)}")
            if not all(isinstance(v, int | float) and math.isfinite(v) and v >= 0 for v in row):
                raise PredictorError(f"class margins must be finite metres >= 0, got {list(row)}")
        if (self.standing_speed, self.walking_speed) != (STANDING_SPEED, WALKING_SPEED):
            raise PredictorError(
                f"class margins calibrated with speed edges {self.standing_speed}, {self.walking_speed} m/s; "
                f"this version classifies at {STANDING_SPEED}, {WALKING_SPEED} m/s: recalibrate"
            )
        object.__setattr__(self, "n", tuple(tuple(c) for c in n))
        object.__setattr__(self, "quantiles", tuple(tuple(float(v) for v in row) for row in q))

    @property
    def horizon(self) -> int:
        return len(self.quantiles[0])

    def per_human(self, classes: np.ndarray, horizon: int) -> np.ndarray:
        """``(horizon, N)`` margins for humans of ``classes`` ``(N,)``: the MPC's ``human_margins``."""
        if horizon > self.horizon:
            raise PredictorError(f"class margins cover {self.horizon} steps, the MPC's horizon is {horizon}")
        table = np.asarray(self.quantiles, dtype=float)[:, :horizon]  # (classes, H)
        return table[np.asarray(classes, dtype=np.int64)].T.copy()

    def to_json(self) -> dict:
        return {
            "names": list(MOTION_CLASSES),
            "standing_speed": self.standing_speed,
            "walking_speed": self.walking_speed,
            "n": [list(c) for c in self.n],
            "quantiles": [list(row) for row in self.quantiles],
        }

    @classmethod
    def from_json(cls, values: object) -> ClassMargins:
        if not isinstance(values, dict) or values.get("names") != list(MOTION_CLASSES):
            raise PredictorError(f"class margins must name the classes {list(MOTION_CLASSES)}")
        try:
            return cls(
                n=tuple(tuple(c) for c in values["n"]),
                quantiles=tuple(tuple(row) for row in values["quantiles"]),
                standing_speed=values["standing_speed"],
                walking_speed=values["walking_speed"],
            )
        except (KeyError, TypeError) as exc:
            raise PredictorError(f"class margins lack or mistype a field ({exc})") from None


def _check_classes(errors: np.ndarray, classes: np.ndarray) -> np.ndarray:
    classes = np.asarray(classes)
    if classes.shape != (len(errors),) or not np.issubdtype(classes.dtype, np.integer):
        raise PredictorError(
            f"classes must be {len(errors)} integers (one per error row), got {classes.shape}"
        )
    if classes.size and (classes.min() < 0 or classes.max() >= len(MOTION_CLASSES)):
        raise PredictorError(f"classes must index {list(MOTION_CLASSES)}")
    return classes


def class_margins(errors: np.ndarray, classes: np.ndarray, alpha: float) -> ClassMargins | None:
    """Each class's ``step_quantiles``; None when some class has too few samples at some step for
    ``alpha`` (no finite margin would be guaranteed for it)."""
    errors = np.asarray(errors, dtype=float)
    classes = _check_classes(errors, classes)
    counts, rows = [], []
    for c in range(len(MOTION_CLASSES)):
        mine = errors[classes == c]
        if len(mine) < min_samples(alpha):
            return None
        quantiles = step_quantiles(mine, alpha)
        if not all(math.isfinite(q) for q in quantiles):
            return None
        counts.append(step_counts(mine))
        rows.append(quantiles)
    return ClassMargins(n=tuple(counts), quantiles=tuple(rows))


def class_coverage(
    errors: np.ndarray, classes: np.ndarray, margins: ClassMargins
) -> tuple[tuple[float, ...], ...]:
    """Per class, the share of its samples within its margin at each step (NaN for an empty column)."""
    errors = np.asarray(errors, dtype=float)
    classes = _check_classes(errors, classes)
    return tuple(
        coverage(errors[classes == c], margins.quantiles[c][: errors.shape[1]])
        if np.any(classes == c)
        else tuple(math.nan for _ in range(errors.shape[1]))
        for c in range(len(MOTION_CLASSES))
    )
