"""The calibration block a command looked up for a controller, handed to the margin lookups made while a
plugin controller is built (``pipelines.loop.controllers``).

A shipped MPC takes the block its command read as an argument (``ControllerReads.calibration``); a plugin is
built as ``Class(spec, env_config, jit=...)``, so one wrapping ``MPCController``, or calling
``spec.margins.located`` itself, looked the block up again: in a sweep's worker, after the driver had checked
the one it hands the shipped controllers (``pipelines.experiments.checked_calibrations``), so a calibrate run
in between had the plugin plan with, and record, a block nobody checked. Within ``handing_calibration`` a
lookup of the same margins for the same predictor (``MarginSpec.stored`` with no ``blocks`` of its caller's)
finds the handed block as the one in force, still checked there as any found block is (its weights' sha256,
the horizon); any other lookup reads calibrations.json as before. This module imports nothing of the margins
(``pipelines.loop.margins`` imports it).
"""

from __future__ import annotations

import contextlib
from collections.abc import Hashable, Iterator
from contextvars import ContextVar
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pathlib import Path

    from predictors.calibration import Calibration

    Located = tuple[Path, Calibration]  # as pipelines.loop.margins names it: a calibrations file, its block

# (the margins, the predictor) a command looked the block up for, and the block; None: nothing handed
_HANDED: ContextVar[tuple[Hashable, str | None, Located] | None] = ContextVar("_HANDED", default=None)


@contextlib.contextmanager
def handing_calibration(margins: Hashable, predictor: str | None, at: Located | None) -> Iterator[None]:
    """Within the block, a lookup of ``margins`` (a ``MarginSpec``) for ``predictor`` that reads the
    calibrations itself finds ``at`` (the file and block the command looked up for them) as the one block in
    force; ``at`` None hands nothing."""
    token = _HANDED.set(None if at is None else (margins, predictor, at))
    try:
        yield
    finally:
        _HANDED.reset(token)


def handed_blocks(margins: Hashable, predictor: str | None) -> list[Located] | None:
    """The blocks in force ``handing_calibration`` hands a lookup of ``margins`` for ``predictor``: its one
    block; None where it hands none for them (other margins, another predictor: the file is read)."""
    handed = _HANDED.get()
    if handed is None or handed[:2] != (margins, predictor):
        return None
    return [handed[2]]
