"""Safety margins on the robot-human distance: which ones a controller plans with, and where they come from.

The paper plans on point predictions: its robot-human constraint (Eq. 11) keeps ``d_min`` from where the
predictor says each human will be, with no allowance for the predictor's error. ``MarginSpec`` chooses an
allowance ``m_k`` per horizon step (``MPCConfig.human_margins``):

* ``none``: no margin, exactly the paper's method (the default);
* ``conformal``: ``m_k`` = the (1 - alpha) split-conformal quantile of the predictor's step-k displacement
  error (Lindemann et al. 2023), read from the predictor's calibration (``crowdmpc calibrate``,
  ``predictors/calibration.py``), calibrated on closed-loop episodes (the default source: humans reacting
  to robots, as the controller will meet them) or on held-out real scenes;
* ``conformal-motion``: ``m_jk`` per human ``j`` and step: the quantile of the human's motion class (new,
  standing, slow, walking; ``predictors.conformal_classes``) at this step, from the same closed-loop
  calibration: coverage within each class, and a standing human no longer gets a walking human's margin;
* ``conformal-shortfall``: as ``conformal-motion``, but each class's quantile is of the *distance shortfall*
  (how much closer the human came to a robot than predicted, at the robot's realised position;
  ``pipelines/experiments/calibrate.py``), the quantity Eq. 11's guarantee needs, rather than of the whole
  displacement error, which bounds it: humans who yield step away from the robot, and that error needs no
  margin;
* ``fixed``: margins given by hand, one per horizon step.

On the command line: ``none``, ``conformal`` (alpha 0.1, closed-loop), ``conformal:0.05``,
``conformal:0.05:real``, ``conformal-motion[:ALPHA]``, ``conformal-shortfall[:ALPHA]``,
``fixed:0.05,0.1,0.15,0.2``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Final, Literal

from crowdsim.world import is_sensor_range
from pipelines.errors import PipelineError

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

    from predictors.calibration import Calibration
    from predictors.calibration_store import ModelKind as Kind
    from predictors.conformal_classes import ClassMargins

    Located = tuple[Path, Calibration]  # a calibrations file and the block of it planned with
    InForce = Sequence[Located]  # every block in force, with its file (stored_calibrations')

MarginMode = Literal["none", "conformal", "conformal-motion", "conformal-shortfall", "fixed"]
CalibrationSource = Literal["closed-loop", "real"]
MARGIN_MODES: Final[tuple[str, ...]] = (
    "none",
    "conformal",
    "conformal-motion",
    "conformal-shortfall",
    "fixed",
)
PER_HUMAN_MODES: Final[tuple[str, ...]] = ("conformal-motion", "conformal-shortfall")  # margins per class
CALIBRATED_MODES: Final[tuple[str, ...]] = ("conformal", *PER_HUMAN_MODES)  # an alpha and a calibration
LABEL_PREFIXES: Final[Mapping[str, str]] = {
    "conformal": "cp",
    "conformal-motion": "cpm",
    "conformal-shortfall": "cps",
}
CALIBRATION_SOURCES: Final[tuple[str, ...]] = ("closed-loop", "real")
DEFAULT_ALPHA: Final[float] = 0.1
MAX_MARGIN: Final[float] = 5.0  # m; a margin beyond this leaves no room to move in a 10 m scene


def class_tables(block: Calibration) -> dict[str, ClassMargins | None]:
    """A calibration block's margins per motion class, by the mode in ``PER_HUMAN_MODES`` that plans with
    them (None where the block has none)."""
    return dict(zip(PER_HUMAN_MODES, (block.classes, block.shortfall), strict=True))


@dataclass(frozen=True)
class MarginSpec:
    """How the controller enlarges the robot-human distance of Eq. 11 (module docstring)."""

    mode: MarginMode = "none"
    alpha: float = DEFAULT_ALPHA  # conformal: miscoverage level, 0 < alpha < 1
    source: CalibrationSource = "closed-loop"  # conformal: which calibration
    values: tuple[float, ...] = ()  # fixed: m_1..m_H in metres
    # calibrated modes: the range (m) of the sensor the robots plan behind, None: they see every human. Not
    # part of the margins' text or label (the world's sensing is): the loop sets it (``behind``), and the
    # block made behind that sensor is planned with where one is stored (find_calibration)
    sensor_range: float | None = None
    sensor_tracks: bool = True  # with sensor_range: whether its tracker reports track lengths

    def __post_init__(self):
        if self.mode not in MARGIN_MODES:
            raise PipelineError(f"unknown margin mode {self.mode!r}; choose from {list(MARGIN_MODES)}")
        if self.source not in CALIBRATION_SOURCES:
            raise PipelineError(
                f"unknown calibration source {self.source!r}; choose from {list(CALIBRATION_SOURCES)}"
            )
        alpha = self.alpha
        if isinstance(alpha, bool) or not isinstance(alpha, int | float) or not 0.0 < alpha < 1.0:
            raise PipelineError(f"margin alpha must be a number in (0, 1), got {alpha!r}")
        from predictors.conformal import MIN_ALPHA

        if alpha < MIN_ALPHA:  # no calibration can have the 10^12 samples its margin needs
            raise PipelineError(f"margin alpha must be at least {MIN_ALPHA:g}, got {alpha!r}")
        values = tuple(self.values)
        for v in values:
            if isinstance(v, bool) or not isinstance(v, int | float) or not 0.0 <= v <= MAX_MARGIN:
                raise PipelineError(
                    f"fixed margins must be numbers in [0, {MAX_MARGIN}] m, got {list(values)}"
                )
        if self.mode in PER_HUMAN_MODES and self.source != "closed-loop":
            raise PipelineError(_closed_loop_only(self.mode))
        if self.sensor_range is not None and not is_sensor_range(self.sensor_range):
            raise PipelineError(
                "margins' sensor_range must be a finite number of metres > 0 (or None: every human seen), "
                f"got {self.sensor_range!r}"
            )
        if not isinstance(self.sensor_tracks, bool):
            raise PipelineError(f"margins' sensor_tracks must be True or False, got {self.sensor_tracks!r}")
        if (self.mode == "fixed") != bool(values):
            raise PipelineError(
                "fixed margins need values (e.g. fixed:0.05,0.1,0.15,0.2); other modes take none"
            )
        object.__setattr__(self, "values", tuple(float(v) for v in values))
        object.__setattr__(self, "alpha", float(alpha))

    def behind(self, sensor_range: float | None, sensor_tracks: bool = True) -> MarginSpec:
        """These margins for robots behind a sensor of ``sensor_range`` m (None: seeing every human) whose
        tracker reports its track lengths or not (``sensor_tracks``): a calibrated mode plans with the block
        made behind that sensor where one is stored; the others are returned as they are."""
        view = (None if sensor_range is None else float(sensor_range), sensor_tracks)
        if self.mode not in CALIBRATED_MODES or view == (self.sensor_range, self.sensor_tracks):
            return self
        return replace(self, sensor_range=view[0], sensor_tracks=view[1])

    @property
    def label(self) -> str:
        """Short and exact, for cell keys, tables and metadata: ``none``, ``cp0.1``, ``cp0.05-real``,
        ``cpm0.1``, ``cps0.05``, ``fixed0.05_0.1_0.15_0.2``."""
        if self.mode == "none":
            return "none"
        if self.mode == "fixed":
            return "fixed" + "_".join(_margin_text(v) for v in self.values)
        from predictors.conformal import alpha_text

        source = "" if self.source == "closed-loop" else f"-{self.source}"  # per-class modes: closed-loop
        return f"{LABEL_PREFIXES[self.mode]}{alpha_text(self.alpha)}{source}"

    def located(
        self, predictor: str | None, horizon: int, sha256: str | None, blocks: InForce | None = None
    ) -> Located | None:
        """The calibrations file and block these margins plan with (None: a mode that needs none), read once
        for ``resolve``, ``resolve_classes`` and ``calibration``: read by each, a controller planned with a
        block a calibrate run replaced between the reads, and its records named the new one. ``blocks``:
        ``stored``'s."""
        return self._located(predictor, horizon, sha256, blocks) if self.mode in CALIBRATED_MODES else None

    def resolve(
        self, predictor: str | None, horizon: int, sha256: str | None, at: Located | None = None
    ) -> tuple[float, ...]:
        """``MPCConfig.human_margins`` for ``predictor`` (its weights' ``sha256``) and ``horizon``: the same
        margins for every human (none for ``conformal-motion``, whose margins ``resolve_classes`` gives);
        ``at``: the block ``located`` gave (None: read here)."""
        if self.mode == "none" or self.mode in PER_HUMAN_MODES:
            return ()
        if self.mode == "fixed":
            if len(self.values) != horizon:
                raise PipelineError(
                    f"fixed margins need one value per horizon step ({horizon}), got {len(self.values)}"
                )
            return self.values
        return tuple((at or self._located(predictor, horizon, sha256))[1].quantiles[:horizon])

    def resolve_classes(
        self, predictor: str | None, horizon: int, sha256: str | None, at: Located | None = None
    ) -> ClassMargins | None:
        """The margins per motion class of ``conformal-motion`` (displacement) and ``conformal-shortfall``
        (distance shortfall); None for every other mode. ``at``: as ``resolve``'s."""
        if self.mode not in PER_HUMAN_MODES:
            return None
        block = (at or self._located(predictor, horizon, sha256))[1]
        table = class_tables(block)[self.mode]
        if table is None:
            from predictors.calibration import remaking_view
            from predictors.calibration_store import recalibrate_command
            from predictors.conformal import alpha_text

            assert predictor is not None  # _block refused None
            view, why = remaking_view(block, (self.sensor_range, self.sensor_tracks))
            command = recalibrate_command(predictor, self.source, self.alpha, *view)
            raise PipelineError(
                f"the {self.source} calibration of {predictor!r} at alpha={alpha_text(self.alpha)} has no "
                f"{self.mode} margins per motion class (made before they existed, or too few samples in a "
                f"class for this alpha); recalibrate with enough episodes: {command} --episodes 200{why}"
            )
        return table

    def _located(
        self, predictor: str | None, horizon: int, sha256: str | None, blocks: InForce | None = None
    ) -> Located:
        at = self.stored(predictor, sha256, blocks=blocks)  # the file holding the block planned with, and it
        self.check_planned(at, at[1].predictor, horizon)
        return at

    def stored(
        self, predictor: str | None, sha256: str | None, kind: Kind = ..., blocks: InForce | None = None
    ) -> Located:
        """``located``'s file and block, unchecked against the horizon; ``kind`` and ``blocks`` (its
        ``stored``: the blocks in force as a caller read them, None: read here): ``locate_calibration``'s."""
        if predictor is None:
            raise PipelineError("conformal margins need a predictor; this controller uses none")
        from predictors.calibration_store import locate_calibration
        from predictors.oracle import ORACLE_PREDICTOR

        if self.source == "real" and predictor == ORACLE_PREDICTOR:  # `calibrate --source real` refuses it
            from predictors.conformal import alpha_text

            raise PipelineError(
                f"the ORCA oracle knows the simulator, not real people, so it has no real calibration: plan "
                f"with its closed-loop one (margins conformal:{alpha_text(self.alpha)}) or leave it out"
            )
        if blocks is None:  # the block its command looked up, where one was handed (a plugin being built)
            from pipelines.loop.margins_handed import handed_blocks

            blocks = handed_blocks(self, predictor)
        return locate_calibration(
            predictor,
            self.source,
            self.alpha,
            sha256=sha256,
            sensor_range=self.sensor_range,
            sensor_tracks=self.sensor_tracks,
            kind=kind,
            stored=blocks,
        )

    def check_planned(self, at: Located, predictor: str, horizon: int, kind: Kind = ...) -> None:
        """PipelineError unless the block ``stored`` gave covers ``horizon`` steps within ``MAX_MARGIN``."""
        path, block = at
        if len(block.quantiles) < horizon:
            raise PipelineError(_short_horizon(self, predictor, len(block.quantiles), horizon, kind))
        self._check_width(block, path, predictor, horizon)

    def _check_width(self, block: Calibration, path: Path, predictor: str, horizon: int) -> None:
        """PipelineError when a margin this mode plans with (its first ``horizon`` steps) is past
        ``MAX_MARGIN``, which fixed margins may not pass either: every step would fall back."""
        table = class_tables(block).get(self.mode)
        rows = [block.quantiles] if self.mode == "conformal" else list(table.quantiles if table else ())
        widest = max((q for row in rows for q in row[:horizon]), default=0.0)  # horizon 0: the records'
        if widest > MAX_MARGIN:
            from predictors.conformal import alpha_text

            raise PipelineError(
                f"the {self.source} calibration of {predictor!r} at alpha={alpha_text(self.alpha)} in "
                f"{path} has a margin of {widest:.4g} m, past the {MAX_MARGIN:g} m any plan in the paper's "
                "scene can keep (a damaged file, or a predictor that far off); recalibrate it or plan with a "
                "larger alpha"
            )

    def calibration(
        self, predictor: str | None, sha256: str | None, at: Located | None = None
    ) -> dict[str, Any] | None:
        """Which stored calibration the margins come from, for the records: when it was made, its data's
        sha256, the zoo whose file holds it ("shipped" or "user": a user's block of a key hides the shipped
        one) and, closed-loop, the conventions its episodes ran under (one block is kept per predictor,
        alpha and sensor range: a recalibration replaces it) and its crowd sizes, with the sensor range its
        robots were behind where they were and whether its tracker reported track lengths. None for margins
        that need none. ``at``: as ``resolve``'s."""
        if self.mode not in CALIBRATED_MODES:
            return None
        from predictors.calibration_store import calibration_zoo

        path, block = at or self._located(predictor, 0, sha256)
        closed_loop = block.source == "closed-loop"
        keys = ("profile", "visibility", "controller", "humans", "sensor_range") if closed_loop else ()
        made = {"created": block.created, "data_sha256": block.data_sha256, "zoo": calibration_zoo(path)}
        made |= {k: block.details[k] for k in keys if k in block.details}
        return made | ({"sensor_tracks": block.sensor_tracks} if "sensor_range" in made else {})

    def describe(self, resolved: tuple[float, ...]) -> dict[str, Any]:
        """What metadata and records state about the margins actually planned with."""
        out: dict[str, Any] = {"mode": self.mode, "label": self.label, "margins_m": list(resolved)}
        if self.mode in CALIBRATED_MODES:
            out |= {"alpha": self.alpha, "source": self.source}
        return out


def calibration_text(calibration: Mapping[str, Any]) -> str:
    """Where a record's calibrated margins came from (``MarginSpec.calibration``), for a summary: "shipped
    calibration of 2026-11-30 20:08 UTC" or "your calibration of ..." (the user zoo's), "calibration of ..."
    in a record from before the zoo was recorded."""
    from datetime import UTC, datetime

    whose = {"shipped": "shipped ", "user": "your "}.get(str(calibration.get("zoo")), "")
    created = str(calibration.get("created"))
    try:
        made = datetime.fromisoformat(created)
    except ValueError:  # a record written by hand: said as it is
        return f"{whose}calibration of {created}"
    zone = "" if made.tzinfo is None else " UTC"
    made = made if made.tzinfo is None else made.astimezone(UTC)
    return f"{whose}calibration of {made:%Y-%m-%d %H:%M}{zone}"


def _margin_text(value: float) -> str:
    """``value`` exactly and short: ``:g`` where it names the value (``0``, ``5``, ``0.05``: the labels, and
    so the cell keys, that sweeps wrote before), else the shortest repr (``0.1234561``, which ``:g`` would
    cut to 0.123456, the label of 0.1234564 too), as ``predictors.conformal.alpha_text`` names alphas."""
    text = f"{value:g}"
    return text if float(text) == value else repr(float(value))


def parse_margins(text: str) -> MarginSpec:
    """``none`` | ``conformal[:ALPHA[:SOURCE]]`` | ``fixed:M1,M2,..`` (module docstring)."""
    if not isinstance(text, str):  # None failed on .strip()
        raise PipelineError(f"margins must be text such as 'none' or 'conformal:0.1', got {text!r}")
    mode, has_alpha, rest = text.strip().partition(":")
    if mode == "none" and not has_alpha:
        return MarginSpec()
    if mode in CALIBRATED_MODES:
        alpha_text, has_source, source = rest.partition(":")  # `conformal:$UNSET` is no default alpha
        alpha = _number(alpha_text, text) if has_alpha else DEFAULT_ALPHA
        source = source if has_source else "closed-loop"
        return MarginSpec(mode, alpha=alpha, source=source)  # type: ignore[arg-type]
    if mode == "fixed" and rest:
        return MarginSpec("fixed", values=tuple(_number(v, text) for v in rest.split(",")))
    raise PipelineError(
        f"bad margins {text!r}; expected none, conformal[:ALPHA[:closed-loop|real]], "
        "conformal-motion[:ALPHA], conformal-shortfall[:ALPHA] or fixed:M1,..,MH (metres)"
    )


def _number(text: str, whole: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise PipelineError(f"bad margins {whole!r}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise PipelineError(f"bad margins {whole!r}: {text!r} is not a finite number")
    return value


def _closed_loop_only(mode: str) -> str:
    """Why a per-class ``mode`` cannot use the real-data calibration: what that calibration computes."""
    why = (
        f"{mode} margins need the closed-loop calibration: the real-data calibration computes one margin per "
        "horizon step for all humans together (those of conformal:ALPHA:real), none per motion class"
    )
    if mode == "conformal-shortfall":  # the shortfall is measured against robots, which real scenes lack
        why += ", and its scenes hold no robot to measure a distance shortfall against"
    return why


def _short_horizon(spec: MarginSpec, predictor: str, covered: int, horizon: int, kind: Kind = ...) -> str:
    """Why a calibration of ``covered`` steps cannot give the margins of a ``horizon``-step MPC, and what
    does: closed-loop calibration predicts with the MPC's default horizon (``crowdmpc calibrate`` cannot
    change it), so only real scenes can be calibrated at another horizon, and the per-class modes cannot
    use them (the real-data calibration computes no margins per motion class)."""
    from predictors.calibration_store import recalibrate_command
    from predictors.conformal import alpha_text

    alpha = alpha_text(spec.alpha)
    why = (
        f"the {spec.source} calibration of {predictor!r} at alpha={alpha} covers {covered} steps, the MPC's "
        f"horizon is {horizon}"
    )
    real = f"{recalibrate_command(predictor, 'real', spec.alpha, kind=kind)} --horizon {horizon}"
    if spec.source == "real":
        return f"{why}; recalibrate the real scenes at that horizon: {real}"
    closed = (
        f"closed-loop calibration runs the MPC at its default horizon of {covered} steps, so plan with a "
        f"horizon of at most {covered} (mpc.horizon)"
    )
    if spec.mode in PER_HUMAN_MODES:  # no per-class margins in a real calibration (_closed_loop_only)
        return f"{why}; {spec.mode} margins come from the closed-loop calibration only, and {closed}"
    from predictors.oracle import ORACLE_PREDICTOR

    if predictor == ORACLE_PREDICTOR:  # no real calibration of the oracle (MarginSpec._block)
        return f"{why}; the ORCA oracle has a closed-loop calibration only, and {closed}"
    return (
        f"{why}; {closed}, or calibrate real scenes at {horizon} steps: {real}, and plan with "
        f"--margins conformal:{alpha}:real"
    )
