"""``crowdmpc zoo calibrations``: the conformal calibration blocks in force, one line each.

A run plans with the block of its predictor, source and alpha made behind its own sensor (or with every
human in view), and a user block hides the shipped block of its key (``predictors.calibration_store``): the
list shows which blocks there are, which zoo each comes from, the margins they give, and whether the
weights they were made for are the ones the zoo holds now (a block of other weights is refused when a run
plans with it).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from predictors.calibration import Calibration

HEADER = [
    "predictor",
    "source",
    "alpha",
    "view",
    "margins (m), k = 1..H",
    "samples",
    "per class",
    "weights",
    "made",
]


def calibration_table(user_dir: Path | None, predictor: str | None = None) -> list[list[str]]:
    """The header and a row per block in force (of ``predictor`` alone where given), the user zoo's first;
    each row ends with the zoo it comes from."""
    from predictors.calibration_store import blocks_in_force, zoo_calibration_files

    files = zoo_calibration_files(user_dir)
    zoo_of = {path: zoo for zoo, path in files}
    rows = [[*HEADER, "zoo"]]
    for path, block in blocks_in_force([path for _, path in files]):
        if predictor is None or block.predictor == predictor:
            rows.append([*_row(block, user_dir), zoo_of[path]])
    return rows


def _row(block: Calibration, user_dir: Path | None) -> list[str]:
    from predictors.conformal import alpha_text

    made = block.sensor_range
    view = "recorded" if block.source == "real" else "every human" if made is None else f"{made:g} m sensor"
    per_class = [name for name, table in (("motion", block.classes), ("shortfall", block.shortfall)) if table]
    return [
        block.predictor,
        block.source,
        alpha_text(block.alpha),
        view,
        " / ".join(f"{q:.2f}" for q in block.quantiles),
        str(min(block.n)),
        ", ".join(per_class) or "-",
        _weights(block, user_dir),
        block.created[:16].replace("T", " "),
    ]


def _weights(block: Calibration, user_dir: Path | None) -> str:
    """Whether ``block`` was made for the weights its predictor has now: "ok", "other" (a run refuses it:
    recalibrate), "no model" (no predictor of that name) or "?" (the zoo's manifest does not read)."""
    from predictors import zoo
    from predictors.errors import PredictorError
    from predictors.registry import PREDICTORS

    if block.predictor in PREDICTORS:
        current = None  # weightless: constant velocity, the ORCA oracle
    else:
        try:
            located = zoo.locate(block.predictor, user_dir)
        except PredictorError:
            return "?"
        if located is None:
            return "no model"
        current = located.entry.sha256
    return "ok" if block.predictor_sha256 == current else "other"


def format_table(rows: list[list[str]]) -> str:
    """``rows`` (the header first) as aligned columns under a rule."""
    widths = [max(len(r[k]) for r in rows) for k in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def run_calibrations(user_dir: Path | None, predictor: str | None) -> int:
    from predictors.calibration_store import zoo_calibration_files

    rows = calibration_table(user_dir, predictor)
    if len(rows) == 1:
        where = " or ".join(str(path) for _, path in zoo_calibration_files(user_dir))
        if predictor is None:
            print(f"no calibrations in {where}")
            return 0
        from predictors import zoo
        from predictors.errors import UnknownPredictor
        from predictors.registry import PREDICTORS

        names = sorted({*PREDICTORS, *(located.entry.name for located in zoo.zoo_entries(user_dir))})
        if predictor not in names:  # a typo, rather than a model never calibrated
            raise UnknownPredictor(predictor, names)
        print(
            f"no calibrations of {predictor!r} in {where}; make them with crowdmpc calibrate --predictor "
            f"{predictor} --source closed-loop|real --alpha 0.1"
        )
        return 0
    print(format_table(rows))
    print(
        "margins: the (1 - alpha) quantile of the displacement error at horizon steps 1..H, those of "
        "--margins conformal:ALPHA[:SOURCE]; per class: the block also holds those of conformal-motion and "
        "conformal-shortfall; weights other: made for other weights, refused until recalibrated"
    )
    return 0
