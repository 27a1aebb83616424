"""The calibration blocks a sweep's workers plan with are those its driver checked.

The driver looks each method's block up from one read of calibrations.json (``check_plan``'s
``planned_margins``; a library run's ``zoo_calibrations``); the workers, other processes (or Ray actors on
other machines), looked each up again, reading the file once a cell as they built its controller: a
`calibrate` run in between (a recalibration under the same alpha keeps the cell key) had them plan with, and
record, margins nobody checked, which only a later resume caught. The driver hands each task its method's
block (``with_checked_calibrations``, ``EpisodeTask.calibration``) and the worker builds the controller with
it (a plugin's own lookups of its margins find it: pipelines.loop.margins_handed): the file is read once a
run, and the resume check checks the records against those same blocks.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, NamedTuple

from pipelines.experiments.tasks import EpisodeTask
from pipelines.loop.margins_read import CheckedBlock

if TYPE_CHECKING:
    from pipelines.loop.controllers import ControllerReads
    from pipelines.loop.margins import InForce
    from pipelines.loop.margins_read import Planned
    from predictors.calibration_store import ModelKind


# by method label: its block, None where its margins need none; a label not there: the worker looks it up
Checked = Mapping[str, "CheckedBlock | None"]


def checked_blocks(planned: Mapping[str, Planned]) -> dict[str, CheckedBlock | None]:
    """``planned`` (``planned_margins``', by method label) to hand the workers; a refusal is left out (the
    plan's checks raise it; else its worker looks the block up, and refuses it, itself)."""
    from pipelines.loop.margins_read import Refused

    return {
        label: None if at is None else CheckedBlock.of(at)
        for label, at in planned.items()
        if not isinstance(at, Refused)
    }


def zoo_calibrations(
    tasks: Iterable[EpisodeTask],
    weights: Mapping[str, str | None],
    blocks: Callable[[], InForce],
    kinds: Mapping[str, ModelKind],
) -> dict[str, CheckedBlock | None]:
    """Each method of ``tasks`` with its block as a library sweep (``run_sweep`` without ``calibrations``)
    hands it, looked up as its controller would (behind its world's sensor, at its horizon, for the weights
    ``weights`` names) in the blocks in force ``blocks`` (``margins_read.read_once``'s): by method label,
    a lookup that refuses left out, for its worker to refuse. ``kinds``: each predictor's model kind as the
    caller located its entry, for the calibrate command a refusal quotes (a name not there: located then)."""
    from pipelines.loop.margins import CALIBRATED_MODES
    from pipelines.loop.margins_read import Refused, look_up
    from pipelines.loop.mpc_setup import mpc_config

    found: dict[str, CheckedBlock | None] = {}
    seen: set[str] = set()
    for task in tasks:
        cell = task.cell
        if cell.method in seen:
            continue
        seen.add(cell.method)
        spec = cell.spec.behind(cell.world.sensor_range, cell.world.sensor_tracks)  # as the worker builds it
        if spec.margins.mode not in CALIBRATED_MODES:
            found[cell.method] = None
            continue
        name = spec.predictor_name
        horizon = mpc_config(spec, world=cell.world.env_config().world()).horizon
        sha256, kind = (None, ...) if name is None else (weights.get(name), kinds.get(name, ...))
        at = look_up(spec.margins, name, horizon, sha256, kind, blocks=blocks)
        if at is not None and not isinstance(at, Refused):
            found[cell.method] = CheckedBlock.of(at)
    return found


def with_checked_calibrations(tasks: list[EpisodeTask], calibrations: Checked) -> list[EpisodeTask]:
    """``tasks``, each holding its method's block in ``calibrations`` (a label not there: none handed)."""
    return [
        dataclasses.replace(task, calibration=calibrations[task.cell.method])
        if task.cell.method in calibrations
        else task
        for task in tasks
    ]


def controller_reads(task: EpisodeTask) -> ControllerReads | None:
    """What the worker's controller of ``task``'s cell takes as read already: the block handed with it (None:
    nothing handed, the controller looks it up)."""
    from pipelines.loop.controllers import ControllerReads

    handed = task.calibration
    if handed is ...:
        return None
    return ControllerReads(calibration=None if handed is None else handed.located())


class CheckedInputs(NamedTuple):
    """What a sweep's driver checked and hands its workers, which its resume and --reuse checks check the
    records against (pipelines.experiments.resume_checks): read again there, a `zoo add --replace` or a
    calibrate run in between had them refuse records of what the workers plan with, or pass others."""

    weights: Mapping[str, str | None]  # the sha256 of each zoo predictor's weights, by name
    calibrations: Checked  # each method's block, by label


def checked_inputs(
    tasks: list[EpisodeTask], weights: Mapping[str, str | None] | None, calibrations: Checked | None
) -> CheckedInputs:
    """``run_sweep``'s ``weights`` and ``calibrations``, those not given read as the run starts: the
    manifests' weights (``zoo_weights``), and each method's block for them from one read of the
    calibrations (``zoo_calibrations``). The entries located for the weights give the model kinds a refused
    lookup's calibrate command names: located again there, a refusal read the manifest once more a method."""
    from pipelines.experiments.checked_weights import zoo_located, zoo_weights
    from pipelines.loop.margins_read import read_once

    kinds: dict[str, ModelKind] = {}  # given weights: the caller located the entries, a refusal locates them
    if weights is None:
        located = zoo_located(tasks)
        weights = zoo_weights(located)
        kinds = {name: None if found is None else found.entry.model for name, found in located.items()}
    if calibrations is None:
        calibrations = zoo_calibrations(tasks, weights, read_once(), kinds)
    return CheckedInputs(weights, calibrations)
