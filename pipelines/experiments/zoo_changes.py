"""Whether the zoo still holds what a sweep's records ran with: the predictor weights (`zoo add --replace`)
and the calibration blocks their margins came from (`calibrate` again under the same alpha and source). A
rerun of a folder whose zoo changed gives other episodes, and said nothing (README promises "same
episodes, metric for metric"); `config show --from-sweep` and `sweep --report-only` say so in one line.

The records are taken a record at a time (``ZooChanges.add``), so that a report that reads the log anyway
gives the note without reading it again.
"""

from __future__ import annotations

import json
from collections.abc import Collection, Hashable
from pathlib import Path
from typing import Any


class ZooChanges:
    """What the records ``add`` was given ran with, against the zoo now. ``cells``: the cell keys whose
    records count (None: every record's): a folder holds the cells of every run swept into it, and a run
    printed or reported plans with its own cells' margins alone (a run with margins none was told a rerun
    "gives other episodes" because another run's conformal block was remade).

    ``add`` keeps each distinct thing a record ran with, and reads nothing: ``note`` reads the zoo, and only
    what the records call for (the calibrations and the weights' registry import torch: a report of a
    folder of constant velocity without margins took 4 s and 90 MB more on a loaded machine)."""

    def __init__(self, cells: Collection[str] | None = None):
        self.cells = cells
        self._weights: dict[str, Any] = {}  # predictor -> sha256 its episodes ran with
        # predictor -> (block, what a rerun plans from) -> the records of distinct margins planned with it
        self._blocks: dict[str, dict[tuple[Any, ...], list[dict[str, Any]]]] = {}
        self._damaged = False  # a record added could not be read: no note

    def add(self, record: dict[str, Any]) -> None:
        if self._damaged:
            return
        try:
            self._add(record)
        except Exception:  # a damaged record: the rerun's own checks say what is wrong with it
            self._damaged = True

    def _add(self, record: dict[str, Any]) -> None:
        name = record.get("predictor")
        if not isinstance(name, str) or (self.cells is not None and record.get("cell") not in self.cells):
            return
        self._weights.setdefault(name, record.get("predictor_sha256"))
        margins = (record.get("config") or {}).get("margins") or {}
        made = margins.get("calibration")
        if isinstance(made, dict) and isinstance(margins.get("alpha"), float):
            # (created, data sha256, alpha): a block; one calibrate run makes its blocks of all alphas at once
            block = (str(made.get("created")), str(made.get("data_sha256")), round(margins["alpha"], 9))
            kept = self._blocks.setdefault(name, {}).setdefault((block, _rerun_key(record)), [])
            # the records of one block state its margins alike: compared as they are, each is not made again
            # into stored_margins' form (which had taken 35 us a record of a 350 us read)
            if all(_margins_of(other) != margins for other in kept):
                kept.append(record)

    def note(self) -> str:
        """The line ("" for none): the weights or margins a rerun takes that differ from the records', and a
        calibration remade with the margins the records planned with (constant_velocity's at 89af3ce, under
        the per-class modes: only its sample counts moved), said as such."""
        try:
            return "" if self._damaged else self._note()
        except Exception:  # a damaged zoo: the rerun's own checks say what is wrong with it
            return ""

    def _note(self) -> str:
        changed = [f"{name}'s weights" for name, sha in self._weights.items() if _other_weights(name, sha)]
        remade = self._remade()
        changed += sorted(f"{name}'s calibration" for name, other in remade.items() if other)
        same = sorted(f"{name}'s calibration" for name, other in remade.items() if not other)
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

    def _remade(self) -> dict[str, bool]:
        """Predictor -> whether a rerun plans with other margins than one of its records of a block the zoo
        no longer holds (its predictors without such records left out)."""
        if not self._blocks:
            return {}
        from predictors.calibration_store import stored_calibrations

        now = {(b.created, b.data_sha256, round(b.alpha, 9)) for _, b in stored_calibrations()}
        planned: dict[Hashable, dict[str, Any] | None] = {}  # _replanned's, by what a rerun plans from
        remade: dict[str, bool] = {}
        for name, blocks in self._blocks.items():
            for (block, _), records in blocks.items():
                if block not in now:
                    remade[name] = remade.get(name, False) or any(_replanned(r, planned) for r in records)
        return remade


def _other_weights(name: str, sha256: Any) -> bool:
    """Whether the zoo's ``name`` now has other weights than ``sha256``, the records'. A record of no weights
    (constant velocity's) whose name no zoo holds is of the same, whatever the registry says: it is not
    imported for it."""
    from predictors import zoo

    if sha256 is None and zoo.locate(name) is None:
        return False
    from predictors.registry import checkpoint_sha256

    return checkpoint_sha256(name) != sha256


def zoo_note(directory: str | Path, cells: Collection[str] | None = None) -> str:
    """``ZooChanges.note`` of the records of ``cells`` (None: every one) in ``directory``'s log; "" for a
    damaged log or zoo, whose rerun's own checks say what is wrong with them."""
    from pipelines.experiments.log import episode_log

    changes = ZooChanges(cells)
    try:
        for _, _, record in episode_log(Path(directory)).scan_shown(None, repair=False):
            changes.add(record)
        return changes.note()
    except Exception:
        return ""


def _margins_of(record: dict[str, Any]) -> Any:
    return (record.get("config") or {}).get("margins")


def _rerun_key(record: dict[str, Any]) -> Hashable:
    """What a rerun of ``record``'s episode plans its margins from: its predictor, margins spec, horizon and
    sensing (a tuple: as JSON it took 10 us a record; a damaged record's unhashable values as JSON)."""
    config = record.get("config") or {}
    margins = config.get("margins") or {}
    key = (
        record.get("predictor"),
        margins.get("mode"),
        margins.get("alpha"),
        margins.get("source"),
        (config.get("mpc") or {}).get("horizon"),
        record.get("sensor_range"),  # None: every human seen
        record.get("sensor_tracks") is not False,
    )
    try:
        hash(key)
    except TypeError:
        return json.dumps(key, default=str)
    return key


def _replanned(record: dict[str, Any], planned: dict[Hashable, dict[str, Any] | None]) -> bool:
    """Whether a rerun of ``record``'s episode plans with other margins than it did, by the rule a resume
    checks them with (``resume_checks.stored_margins``: sample counts aside). ``planned``: what a rerun
    plans with, by ``_rerun_key`` (a sweep's records share a few)."""
    from pipelines.experiments.resume_checks import margins_planned, stored_margins
    from pipelines.loop.margins import MarginSpec

    key = _rerun_key(record)
    if key not in planned:
        config = record.get("config") or {}
        margins = config.get("margins") or {}
        horizon: Any = (config.get("mpc") or {}).get("horizon")
        sensing = (record.get("sensor_range"), record.get("sensor_tracks") is not False)
        try:
            spec = MarginSpec(margins["mode"], margins["alpha"], margins["source"]).behind(*sensing)
            planned[key] = margins_planned(spec, record.get("predictor"), horizon)
        except Exception:  # no block a rerun plans with (or a damaged record): it does not plan the same
            planned[key] = None
    return planned[key] is None or stored_margins(record) != planned[key]
