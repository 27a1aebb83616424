"""Storing ``crowdmpc calibrate``'s blocks in the user zoo's calibrations file: after the held-out run, so
that an interrupted or failed command leaves the user's calibrations as they were, or before it when its
episodes plan with them, the earlier blocks put back if the run stops; never a block without margins per
motion class over one that has them."""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Iterator
from typing import TYPE_CHECKING

from pipelines.errors import PipelineError
from predictors.errors import PredictorError

if TYPE_CHECKING:
    from pipelines.loop.margins import MarginSpec


def plans_with_new_blocks(args: argparse.Namespace, holdout_margins: MarginSpec) -> bool:
    """Whether the held-out episodes plan with margins of a block this run stores (--holdout-margins
    conformal:A with A one of --alpha), which must then be stored before them."""
    from pipelines.loop.margins import CALIBRATED_MODES
    from predictors.calibration import same_alpha

    return (
        not args.dry_run
        and args.holdout
        and args.source == "closed-loop"
        and holdout_margins.mode in CALIBRATED_MODES
        and holdout_margins.source == "closed-loop"
        and any(same_alpha(holdout_margins.alpha, a) for a in args.alpha)
    )


@contextlib.contextmanager
def storing(blocks: list, args: argparse.Namespace) -> Iterator[None]:
    """Store ``blocks`` (not with --dry-run) once the held-out run inside has finished: an interrupted or
    failed command leaves the user's calibrations as they were. When the held-out episodes plan with these
    blocks they are stored first, and the earlier blocks of their keys are put back if the run stops (blocks
    another calibrate stored meanwhile stay)."""
    from pipelines.loop.margins import parse_margins
    from predictors.calibration import calibrations_path, read_calibration_file

    if args.dry_run:
        yield
        return
    _check_keeps_class_margins(blocks, args)
    if not plans_with_new_blocks(args, parse_margins(args.holdout_margins)):
        yield
        _store(blocks)
        return
    path = calibrations_path()
    before = read_calibration_file(path) if path.exists() else None
    _store(blocks)
    try:
        yield
    except BaseException:  # Ctrl-C too
        _put_back(blocks, before)
        raise


def _store(blocks: list) -> None:
    from predictors.calibration import save_calibration

    for block in blocks:
        path = save_calibration(block)
    print(f"wrote {len(blocks)} block(s) to {path}")


def _put_back(blocks: list, before: list | None) -> None:
    """The calibrations file without ``blocks``: the blocks of their keys in ``before`` (the file's blocks
    before this run; None: there was no file) back in their place."""
    from predictors.calibration import undo_calibrations

    try:
        path = undo_calibrations(blocks, before)
    except (OSError, PredictorError) as exc:
        raise PipelineError(
            f"the held-out run stopped and the calibrations it stored could not be taken back ({exc})"
        ) from None
    print(f"the held-out run did not finish: its blocks are taken out of {path}, the earlier ones put back")


def _check_keeps_class_margins(blocks: list, args: argparse.Namespace) -> None:
    """Refuse to store a block without margins per motion class in place of one that has them (the shipped
    block, or the user's earlier one): a short trial run would otherwise make conformal-motion and
    conformal-shortfall, which docs/examples/safe_crossing.toml plans with, refuse that predictor."""
    from pipelines.loop.margins import class_tables
    from predictors.calibration import stored_calibrations
    from predictors.conformal import alpha_text

    in_force = stored_calibrations()
    losing = []
    for block in blocks:
        new = class_tables(block)
        for path, old in in_force:
            if old.matches(*block.key()) and any(
                new[mode] is None and had is not None for mode, had in class_tables(old).items()
            ):
                losing.append(f"alpha {alpha_text(block.alpha)} (in force: {path})")
    if losing:
        raise PipelineError(
            f"not stored: {args.predictor}'s {args.source} calibration at {', '.join(losing)} has margins "
            "per motion class and these blocks have none (too few samples in a class); run more --episodes "
            "(default 200), or measure without storing with --dry-run"
        )
