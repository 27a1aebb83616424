"""The calibration block some margins plan with, looked up once for a command's notes and for what plans with
it, a refusal included: a lookup that refused was made again by each calibration note (the manifest for the
weights' sha256, then calibrations.json) and once more where the refusal is raised, so `simulate --margins
conformal:0.37` read manifest.json 13 times and calibrations.json 7 times before its one line."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from pipelines.errors import PipelineError
from predictors.errors import PredictorError, short_repr

if TYPE_CHECKING:
    from collections.abc import Callable
    from types import EllipsisType

    from pipelines.loop.margins import InForce, Located, MarginSpec
    from predictors.calibration import Calibration
    from predictors.calibration_store import ModelKind


@dataclass(frozen=True)
class Refused:
    """A lookup of the block some margins plan with that refused. ``error`` is raised where the block would
    be planned with (the controller, after its own checks; a sweep's margins check, after the couplings'),
    so the refusal and what comes before it read as they did; the notes describe ``found``, the block stored
    for the predictor, alpha and view (one of too few steps, a margin too wide, no per-class margins), None
    where none was found (the refusal says so)."""

    error: Exception
    found: Located | None = None

    def __post_init__(self):
        if not isinstance(self.error, Exception):
            raise PipelineError(f"Refused.error must be an exception, got {short_repr(self.error)}")
        if self.found is not None and not (isinstance(self.found, tuple) and len(self.found) == 2):
            raise PipelineError(f"Refused.found must be a (file, block) pair or None, got {self.found!r:.80}")


if TYPE_CHECKING:
    Planned = Located | None | Refused  # what a lookup gave: the block, None (no block needed), a refusal


def look_up(
    margins: MarginSpec,
    predictor: str | None,
    horizon: int,
    sha256: str | None,
    kind: ModelKind = ...,
    blocks: Callable[[], InForce] | None = None,
) -> Planned:
    """``margins.located`` as a controller of ``horizon`` steps planning with ``predictor`` (its weights'
    ``sha256``) reads it, with its per-class margins (``resolve_classes``); a refusal of either (a
    ``PipelineError`` or ``PredictorError``) comes back as ``Refused``, other errors go on. ``kind``: that of
    ``predictor``'s zoo entry, as the caller located it, for the calibrate command a refusal quotes;
    ``blocks``: the blocks in force, as ``read_once`` read them for every lookup of a plan (None: read
    here)."""
    from pipelines.loop.margins import CALIBRATED_MODES

    if margins.mode not in CALIBRATED_MODES:
        return None
    try:
        at = margins.stored(predictor, sha256, kind, None if blocks is None else blocks())
    except (PipelineError, PredictorError) as exc:
        return Refused(exc)
    try:
        margins.check_planned(at, at[1].predictor, horizon, kind)
        margins.resolve_classes(predictor, horizon, sha256, at)
    except (PipelineError, PredictorError) as exc:
        return Refused(exc, at)
    return at


def read_once() -> Callable[[], InForce]:
    """The calibration blocks in force (``stored_calibrations``), read at the first call and given again,
    or their refusal (a damaged file) raised again, at every later one: the lookups of a plan's
    predictors each read calibrations.json, so that a calibrate run between the reads had one predictor's
    margins checked against another content of the file than the next one's."""
    read: list[InForce | Exception] = []

    def blocks() -> InForce:
        if not read:
            from predictors.calibration_store import stored_calibrations

            try:
                read.append(stored_calibrations())
            except (PipelineError, PredictorError) as exc:
                read.append(exc)
        if isinstance(read[0], Exception):
            raise read[0]
        return read[0]

    return blocks


def load_refused(
    margins: MarginSpec, predictor: str, sha256: str | None, kind: ModelKind, error: Exception
) -> Refused:
    """A predictor whose load refused (``error``, raised where the controller loads it, after the notes):
    the notes describe the block stored for its zoo entry's weights (``sha256``), unchecked against a
    horizon, None where none is found, as each note looked it up. Looked up by each note and loaded again
    by the controller, a corrupt social_lstm_eth.pt had `simulate --margins conformal:0.1` read manifest.json
    7 times, calibrations.json 5 times and the weights twice before its one line."""
    from pipelines.loop.margins import CALIBRATED_MODES

    if margins.mode not in CALIBRATED_MODES:
        return Refused(error)
    try:
        return Refused(error, margins.stored(predictor, sha256, kind))
    except (PipelineError, PredictorError):  # the notes say nothing of a block they cannot find
        return Refused(error)


def as_planned(
    margins: MarginSpec, read: Planned | EllipsisType, predictor: str, horizon: int, sha256: str | None
) -> Located | None:
    """The block a controller plans with: ``read`` as its command read it (``...``: read here), the refusal
    of a ``Refused`` raised now, at the controller's turn."""
    if isinstance(read, Refused):
        raise read.error
    return margins.located(predictor, horizon, sha256) if read is ... else read


def block_of(read: Planned | EllipsisType) -> Calibration | None | EllipsisType:
    """The block the calibration notes describe of a lookup's result (``...``: none made, they look it up)."""
    found = read.found if isinstance(read, Refused) else read
    return found if found is ... or found is None else found[1]


@dataclass(frozen=True)
class CheckedBlock:
    """A calibration block as a sweep's driver located it, handed to its workers
    (pipelines.experiments.checked_calibrations): its file, whether that file is the shipped zoo's, and
    the block. The records name the zoo the block came from (``MarginSpec.calibration``) by its file: a Ray
    node elsewhere has the package, hence the shipped file, at another path, where the driver's read as a
    user zoo's."""

    file: Path
    shipped: bool
    block: Calibration

    @classmethod
    def of(cls, at: Located) -> CheckedBlock:
        from predictors.zoo import is_shipped

        return cls(at[0], is_shipped(at[0].parent), at[1])

    def located(self) -> Located:
        """The (file, block) a controller plans with here: a shipped block in this machine's shipped file."""
        from predictors.zoo import checkpoints_dir

        return (checkpoints_dir() / self.file.name if self.shipped else self.file), self.block
