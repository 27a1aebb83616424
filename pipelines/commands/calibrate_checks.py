"""``crowdmpc calibrate``'s own lines on the blocks it is asked for or makes: its refusal of a --sensor-range
beyond the bound that names the blocks made behind it before the bound, and its notes on margins too wide for
a plan to keep (the notes of runs planning with calibrated margins are
``pipelines.commands.calibration_notes``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from predictors.calibration import Calibration


def wide_margins_notes(blocks: Sequence[Calibration]) -> list[str]:
    """calibrate's line for each block with margins past ``MAX_MARGIN`` (of ``conformal``, or of a class of
    ``conformal-motion`` or ``conformal-shortfall``), naming the first horizon step that passes it: a run
    planning with those margins at a horizon reaching that step refuses the block
    (``MarginSpec._check_width``), which calibrate stored without a word, in the place of its key's block."""
    from pipelines.loop.margins import MAX_MARGIN, class_tables
    from predictors.conformal import alpha_text

    notes = []
    for block in blocks:
        tables = {"conformal": [block.quantiles]}
        tables |= {mode: list(table.quantiles) for mode, table in class_tables(block).items() if table}
        for mode, rows in tables.items():
            past = [k + 1 for k in range(block.horizon) if any(row[k] > MAX_MARGIN for row in rows)]
            if past:
                notes.append(
                    f"note: alpha {alpha_text(block.alpha)}: the {mode} margins pass the {MAX_MARGIN:g} m "
                    f"any plan in the paper's scene can keep from horizon step {past[0]} on "
                    f"({max(max(row) for row in rows):.4g} m at the widest): runs planning with them at a "
                    f"horizon of {past[0]} or more refuse this block"
                )
    return notes


def sensor_range_refusal(predictor: str, sensor_range: float | None) -> str | None:
    """calibrate's refusal of a --sensor-range beyond ``crowdsim.world.SENSOR_RANGE`` (None: within it, or
    none given; no distance at all is ``ClosedLoopPlan``'s to refuse), naming the calibrations file that
    holds blocks of ``predictor`` made behind it before the bound: the same calibrate again was refused in
    the bound's words alone, as if none were stored, where they stay in force (a run behind the nearest
    range plans with one)."""
    from crowdsim.world import is_sensor_range, sensor_range_refused
    from predictors.calibration_store import stored_calibrations
    from predictors.errors import PredictorError

    if sensor_range is None or not is_sensor_range(sensor_range):
        return None
    refused = sensor_range_refused(sensor_range)
    if refused is None:
        return None
    try:
        stored = stored_calibrations()
    except (PredictorError, OSError):  # a file calibrate cannot read: the refusal as for any range
        stored = []
    made = [(path, b) for path, b in stored if b.predictor == predictor and b.sensor_range == sensor_range]
    if not made:
        return f"--sensor-range: {refused}"
    files = ", ".join(sorted({str(path) for path, _ in made}))
    alphas = ", ".join(f"{b.alpha:g}" for _, b in made)
    return (
        f"--sensor-range: {refused}; {files} holds {predictor}'s closed-loop margins behind a "
        f"{sensor_range:g} m sensor (alpha {alphas}), made before that bound: they stay, as `crowdmpc zoo "
        "calibrations` lists them"
    )
