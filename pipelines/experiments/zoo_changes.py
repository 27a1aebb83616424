"""Whether the zoo still holds what a sweep's records ran with: the predictor weights (`zoo add --replace`)
and the calibration blocks their margins came from (`calibrate` again under the same alpha and source). A
rerun of a folder whose zoo changed gives other episodes, and said nothing (README promises "same
episodes, metric for metric"); `config show --from-sweep` and `sweep --report-only` say so in one line.

The records are taken a record at a time (``ZooChanges.add``), so that a report that reads the log anyway
gives the note without reading it again.
"""

from __future__ import annotations

import json
from collections.abc import Collection
from pathlib import Path
from typing import Any


class ZooChanges:
    """What the records ``add`` was given ran with, against the zoo now. ``cells``: the cell keys whose
    records count (None: every record's): a folder holds the cells of every run swept into it, and a run
    printed or reported plans with its own cells' margins alone (a run with margins none was told a rerun
    "gives other episodes" because another run's conformal block was remade)."""

    def __init__(self, cells: Collection[str] | None = None):
        from predictors.calibration_store import stored_calibrations

        self.cells = cells
        # (created, data sha256, alpha): a block; one calibrate run makes its blocks of every alpha at once
        self._now = {(b.created, b.data_sha256, round(b.alpha, 9)) for _, b in stored_calibrations()}
        self._weights: dict[str, Any] = {}  # predictor -> sha256 its episodes ran with
        # predictor -> whether a rerun plans with other margins than one of its records of a remade block
        self._remade: dict[str, bool] = {}
        self._planned: dict[str, dict[str, Any] | None] = {}  # _replanned's, by what a rerun plans from

    def add(self, record: dict[str, Any]) -> None:
        name = record.get("predictor")
        if not isinstance(name, str) or (self.cells is not None and record.get("cell") not in self.cells):
            return
        self._weights.setdefault(name, record.get("predictor_sha256"))
        margins = (record.get("config") or {}).get("margins") or {}
        made = margins.get("calibration")
        if isinstance(made, dict) and isinstance(margins.get("alpha"), float):
            block = (str(made.get("created")), str(made.get("data_sha256")), round(margins["alpha"], 9))
            if block not in self._now and not self._remade.get(name):
                self._remade[name] = _replanned(record, self._planned)

    def note(self) -> str:
        """The line ("" for none): the weights or margins a rerun takes that differ from the records', and a
        calibration remade with the margins the records planned with (constant_velocity's at 89af3ce, under
        the per-class modes: only its sample counts moved), said as such."""
        from predictors.registry import checkpoint_sha256

        weights = self._weights.items()
        changed = [f"{name}'s weights" for name, sha in weights if checkpoint_sha256(name) != sha]
        changed += sorted(f"{name}'s calibration" for name, other in self._remade.items() if other)
        same = sorted(f"{name}'s calibration" for name, other in self._remade.items() if not other)
        notes = []
        if changed:
            notes.append(
                f"The zoo no longer holds what this sweep ran with ({', '.join(changed)} changed since), so "
                "a rerun gives other episodes; `crowdmpc compare OLD NEW` names what differs."
            )
        # the records of a rerun name another block, which compare shows: said, but no other episodes
        if same:
            notes.append(
                f"{', '.join(same)} {'was' if len(same) == 1 else 'were'} remade since with the margins "
                "this sweep planned with, so a rerun plans with the same margins (its records name the new "
                "calibration)."
            )
        return " ".join(notes)


def zoo_note(directory: str | Path, cells: Collection[str] | None = None) -> str:
    """``ZooChanges.note`` of the records of ``cells`` (None: every one) in ``directory``'s log; "" for a
    damaged log or zoo, whose rerun's own checks say what is wrong with them."""
    from pipelines.experiments.log import episode_log

    try:
        changes = ZooChanges(cells)
        for _, _, record in episode_log(Path(directory)).scan_shown(None, repair=False):
            changes.add(record)
        return changes.note()
    except Exception:
        return ""


def _replanned(record: dict[str, Any], planned: dict[str, dict[str, Any] | None]) -> bool:
    """Whether a rerun of ``record``'s episode plans with other margins than it did, by the rule a resume
    checks them with (``resume_checks.stored_margins``: sample counts aside). ``planned``: what a rerun
    plans with, kept by its inputs (a sweep's records share a few)."""
    from pipelines.experiments.resume_checks import margins_planned, stored_margins
    from pipelines.loop.margins import MarginSpec

    config = record.get("config") or {}
    margins = config.get("margins") or {}
    horizon: Any = (config.get("mpc") or {}).get("horizon")
    sensing = (record.get("sensor_range"), record.get("sensor_tracks") is not False)  # None: every human seen
    inputs = [
        record.get("predictor"),
        margins.get("mode"),
        margins.get("alpha"),
        margins.get("source"),
        horizon,
    ]
    key = json.dumps([*inputs, *sensing], sort_keys=True, default=str)
    if key not in planned:
        try:
            spec = MarginSpec(margins["mode"], margins["alpha"], margins["source"]).behind(*sensing)
            planned[key] = margins_planned(spec, record.get("predictor"), horizon)
        except Exception:  # no block a rerun plans with (or a damaged record): it does not plan the same
            planned[key] = None
    return planned[key] is None or stored_margins(record) != planned[key]
