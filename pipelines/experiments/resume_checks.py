"""What a resumed sweep must match in the records it extends: the predictor weights and the margins each cell
plans with now, and the recording a replayed crowd plays, against those its records state
(pipelines.experiments.sweep checks them before any episode runs, so a table never silently mixes two
predictors, two margin sets or two crowds).
"""

from __future__ import annotations

import json
import shlex
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipelines.errors import PipelineError
from pipelines.experiments.log import EPISODES_FILE, episode_log
from pipelines.experiments.run_lines import run_number
from pipelines.experiments.tasks import Cell, EpisodeTask
from pipelines.plain_json import plain

if TYPE_CHECKING:
    from types import EllipsisType

    from pipelines.experiments.checked_calibrations import CheckedInputs
    from pipelines.loop.margins import InForce, Located, MarginSpec
    from pipelines.loop.margins_read import CheckedBlock


def read_recorded(
    out: Path,
    tasks: list[EpisodeTask],
    progress: bool | None,
    *,
    repair: bool = False,
    records: Callable[[int, bytes, dict[str, Any]], None] | None = None,
    checked: CheckedInputs | None = None,
) -> ResumeChecks:
    """Which of ``tasks`` the log of ``out`` holds, as a resume reads it (a record at a time, a bar when
    ``progress``) and checked (``ResumeChecks.check``): what a resume runs is the rest. ``repair``: cut a torn
    last line off the log (only the sweep holding its lock may); ``records``: called with each record as
    ``EpisodeLog.scan`` gives it; ``checked``: ``ResumeChecks``'."""
    recorded = ResumeChecks(out, tasks, checked=checked)
    for offset, line, record in episode_log(out).scan_shown(progress, repair=repair):
        recorded.add(record)
        if records is not None:
            records(offset, line, record)
    recorded.check()
    return recorded


class ResumeChecks:
    """What a resumed sweep reads of the records it extends, a record at a time (``add``), and the checks
    (``check``): which planned episodes are recorded, and the predictor weights and the margins their records
    state, each distinct value once with the first planned episode that states it. A resume held each
    record's key and these fields, 1.2 KB an episode before its first new one ran; now a byte an episode and,
    while the log is read, the plan's index by key: a resume of 100,000 recorded episodes with nothing left
    to run (benchmarks/sweep_log_scale.py's) peaked at 256 MB, now 154 MB."""

    def __init__(
        self,
        out: Path,
        tasks: list[EpisodeTask],
        *,
        reused: bool = False,
        checked: CheckedInputs | None = None,
    ):
        """``reused``: ``out`` is another sweep's folder whose records ``sweep --reuse`` would take
        (pipelines.experiments.reuse), not the folder this sweep extends. ``checked``: the sha256 of each zoo
        predictor's weights and the block of each method as the sweep hands them to its workers
        (``run_sweep``'s), which the records are checked against (a name or method not there: looked up
        here; None: all looked up here)."""
        self.out = out
        self._weights = {} if checked is None else checked.weights
        self._calibrations = {} if checked is None else checked.calibrations
        self.reused = reused
        self.tasks = tasks
        self._index = {t.key: i for i, t in enumerate(tasks)}
        self.done = bytearray(len(tasks))  # 1 where the log holds the planned episode
        # (predictor, its sha256) as JSON -> (first plan index, predictor, sha256)
        self._predictors: dict[str, tuple[int, Any, Any]] = {}
        # (cell key, its margins as JSON) -> (first plan index, margins, the calibration its record names)
        self._margins: dict[tuple[str, str], tuple[int, dict[str, Any], Any]] = {}
        # (replayed crowd, its file's sha256) -> first plan index
        self._crowds: dict[tuple[str, str], int] = {}
        self.outside = 0  # records of episodes this run does not plan (another run's options)
        self._outside_key: str | None = None  # the first of them
        # the runs (sweep.json's numbers) that recorded an episode; None once a record names none (written
        # before records kept their run): then every run may have
        self.runs_recorded: set[int] | None = set()
        self.last_run = 0  # the highest run a record names, whatever others lack (run_lines.lost_runs)

    def add(self, record: dict[str, Any]) -> None:
        run = run_number(record)
        if run is not None:
            self.last_run = max(self.last_run, run)
        if self.runs_recorded is not None:
            if run is not None:
                self.runs_recorded.add(run)
            else:
                self.runs_recorded = None
        i = self._index.get(record["key"])
        if i is None:  # not of the plan: neither run nor checked, but counted (outside_note)
            self.outside += 1
            self._outside_key = self._outside_key or str(record["key"])
            return
        self.done[i] = 1
        name, sha256 = record.get("predictor"), record.get("predictor_sha256")
        _keep_first(self._predictors, json.dumps([name, sha256], sort_keys=True), (i, name, sha256))
        crowd, sha256 = self.tasks[i].cell.world.crowd, record.get("crowd_sha256")
        if crowd != "orca" and isinstance(sha256, str):  # a record from before it was kept says nothing
            self._crowds.setdefault((crowd, sha256), i)
        stored = stored_margins(record)
        if stored is not None:
            key = (self.tasks[i].cell.key, json.dumps(stored, sort_keys=True))
            made = ((record.get("config") or {}).get("margins") or {}).get("calibration")
            _keep_first(self._margins, key, (i, stored, made))

    def recorded(self, i: int) -> bool:
        return bool(self.done[i])

    def outside_note(self) -> str | None:
        """A line for a log holding episodes this run does not plan (a resume with fewer episodes per cell,
        other crowd sizes or settings), None otherwise: the report is of the plan's episodes, and those
        dropped out of table.md and cells.csv without a word."""
        if not self.outside:
            return None
        return (
            f"note: {self.out / EPISODES_FILE} holds {self.outside} episode(s) this run does not plan (e.g. "
            f"{self._outside_key}): table.md, cells.csv and episodes.csv report this run's plan only; "
            f"`crowdmpc config show --from-sweep {shlex.quote(str(self.out))} --run N` prints what earlier "
            "run N planned"
        )

    def check(self) -> None:
        """The predictors, then the margins, then the replayed crowds: each planned episode's record, in the
        plan's order."""
        self._index.clear()  # not held while the workers run
        self._check_predictors()
        self._check_margins()
        self._check_crowds()

    def _check_predictors(self) -> None:
        """Refuse to extend a cell whose records came from other weights than the zoo holds now (a retrained
        model): its table would silently mix two predictors. Now: the weights the sweep checked, which its
        workers load (the manifest, read again, may name others a `zoo add --replace` put in since)."""
        from predictors.registry import checkpoint_sha256

        current: dict[str | None, str | None] = {}  # predictor name (None in a record without one) -> sha256
        log = self.out / EPISODES_FILE
        for i, name, sha256 in sorted(self._predictors.values(), key=lambda first: first[0]):
            if name not in current:
                current[name] = self._weights[name] if name in self._weights else checkpoint_sha256(name)
            if sha256 != current[name]:
                raise PipelineError(
                    f"{log} holds episodes of {self.tasks[i].cell.key} run with predictor {name!r} of "
                    f"sha256 {sha256}, but the zoo's {name!r} is now {current[name]}; "
                    f"{self._remedy('the new weights')}"
                )

    def _check_margins(self) -> None:
        """Refuse to extend a cell whose records planned with other margins than the cell resolves now (a
        recalibration under the same alpha and source keeps the cell key): its table would silently mix two
        margin sets. Records without margins (baselines, records from before the config was kept) say
        nothing."""
        from pipelines.loop.margins_read import read_once

        current: dict[str, dict[str, Any]] = {}  # cell key -> its margins now
        in_force = read_once()  # the calibrations read once for every cell, not once a cell
        log = self.out / EPISODES_FILE
        for i, stored, made in sorted(self._margins.values(), key=lambda first: first[0]):
            key = self.tasks[i].cell.key
            cell = self.tasks[i].cell
            handed = self._calibrations.get(cell.method, ...)
            if key not in current:
                current[key] = planned_margins(cell, in_force, handed)
            if stored != current[key]:
                raise PipelineError(
                    f"{log} holds episodes of {key} planned with {_margins_change(stored, current[key])}: "
                    f"{_why_changed(cell, made, handed)}; {self._remedy('the new margins')}"
                )

    def _check_crowds(self) -> None:
        """Refuse to extend a cell whose records replayed people from another file than the data directory
        holds now (another $CROWDMPC_DATA, an edited recording): its table would silently mix two crowds."""
        from pipelines.loop.replay_data import recording_path, recording_sha256

        log = self.out / EPISODES_FILE
        for (crowd, sha256), i in sorted(self._crowds.items(), key=lambda item: item[1]):
            now = recording_sha256(crowd)
            if sha256 != now:
                key = self.tasks[i].cell.key
                raise PipelineError(
                    f"{log} holds episodes of {key} replaying people from a file of sha256 {sha256}, but "
                    f"{recording_path(crowd)} is now {now}; "
                    f"{self._remedy('the new data (or set CROWDMPC_DATA back)')}"
                )

    def _remedy(self, what: str) -> str:
        """What to do about a refused record: a new folder for what changed, or, for records ``sweep --reuse``
        would take, no taking (they are not the episodes the cells plan now)."""
        if self.reused:
            return "they are not episodes of this plan now: run the sweep without --reuse"
        # a report runs none of these checks: the folder still reports what it holds, which went unsaid; the
        # command quoted as a shell needs it, to be pasted as it is (a folder named "my runs")
        out = shlex.quote(str(self.out))
        return (
            f"use another --out for {what}, or `crowdmpc sweep --report-only --out {out}` to report the "
            "episodes it holds"
        )


def _why_changed(cell: Cell, made: Any, handed: CheckedBlock | None | EllipsisType = ...) -> str:
    """Why ``cell``'s margins moved since its record of calibration ``made`` (None: a record that names none):
    the block it planned with was made again, both named (constant_velocity's closed-loop blocks at 89af3ce,
    m_1 moved by up to 1.5e-3 m), else a guess; a refusal had said "(recalibrated?)" of them too.
    ``handed``: the block the cell's workers plan with, whose margins the refusal gives (``...``: looked up
    here; read again, a calibrate run since the plan's checks had the refusal date another block)."""
    from pipelines.loop.margins import calibration_text
    from predictors.registry import checkpoint_sha256

    spec = cell.spec.behind(cell.world.sensor_range, cell.world.sensor_tracks)  # as planned_margins'
    try:
        if handed is ...:
            now = spec.margins.calibration(spec.predictor_name, checkpoint_sha256(spec.predictor_name))
        else:
            now = None if handed is None else spec.margins.calibration(None, None, handed.located())
    except Exception:  # no block now (planned_margins found one a moment ago): said as before
        now = None
    fields = ("created", "data_sha256")
    if not isinstance(made, dict) or now is None or all(made.get(f) == now[f] for f in fields):
        return "they changed since the records were made (recalibrated?)"
    margins = spec.margins
    return (
        f"{spec.predictor_name}'s {margins.source} calibration at alpha {margins.alpha:g} was made again "
        f"after the records (records: {calibration_text(made)}, now: {calibration_text(now)})"
    )


def _margins_change(was: dict[str, Any], now: dict[str, Any]) -> str:
    """What changed between two ``planned_margins``: the margins themselves, else the first motion class
    whose margins differ (per-class modes plan with those alone, and their common margins are [] on both
    sides: the refusal had read "margins [] m, but ... now [] m")."""
    if was["margins_m"] != now["margins_m"]:
        old_m, new_m = _apart(was["margins_m"], now["margins_m"])
        return f"margins {old_m} m, but the cell's margins are now {new_m} m"
    old, new = (c if isinstance(c, dict) else {} for c in (was["classes"], now["classes"]))
    names, a_rows, b_rows = old.get("names"), old.get("quantiles"), new.get("quantiles")
    # a damaged record's rows: compare what both hold
    differ = [(n, a, b) for n, a, b in zip(names or [], a_rows or [], b_rows or [], strict=False) if a != b]
    if not a_rows or not b_rows:
        if a_rows:
            return "margins per motion class, where the cell now plans with none"
        return "no margins per motion class, where the cell now plans with them"
    if not differ:  # the classes themselves changed (their speeds)
        return "other motion classes than the cell's now"
    name, a, b = differ[0]
    more = f" (and {len(differ) - 1} more class{'es' * (len(differ) > 2)})" if len(differ) > 1 else ""
    a_text, b_text = _apart(a, b)
    return f"margins per motion class, {name} {a_text} m, but the cell's are now {b_text} m{more}"


def _apart(was: Any, now: Any) -> tuple[str, str]:
    """Two lists of margins (m) rounded to the millimetre, or to as many more decimals as tell them apart: a
    calibration's quantiles have 17 digits, which the common margins were printed with, and the class
    margins' millimetres printed a move of 1e-5 m as the same margins twice ("[0.183] m, but the cell's are
    now [0.183] m"). Each value is the shortest repr of its rounding (0.18, not 0.180); what is not a list of
    numbers (a damaged record) is shown as it is."""
    if not all(_numbers(values) for values in (was, now)):
        return str(was), str(now)
    for decimals in range(3, 18):
        texts = tuple(_rounded(values, decimals) for values in (was, now))
        if texts[0] != texts[1]:
            return texts[0], texts[1]
    return str(was), str(now)  # the same to 17 decimals: in full


def _numbers(values: Any) -> bool:
    return isinstance(values, list) and all(isinstance(v, int | float) for v in values)


def _rounded(values: list[float], decimals: int) -> str:
    return "[" + ", ".join(repr(round(float(v), decimals)) for v in values) + "]"


def _keep_first(firsts: dict[Any, tuple[Any, ...]], key: Any, value: tuple[Any, ...]) -> None:
    """``firsts[key]``: the ``value`` of the smallest plan index (its first item)."""
    if key not in firsts or value[0] < firsts[key][0]:
        firsts[key] = value


def planned_margins(
    cell: Cell,
    blocks: Callable[[], InForce] | None = None,
    handed: CheckedBlock | None | EllipsisType = ...,
) -> dict[str, Any]:
    """The margins ``cell``'s MPC plans with now, as its records state them (MPCController.describe's
    "margins": the same for every human, and per motion class), in their JSON form; ``blocks``:
    ``margins_planned``'s; ``handed``: the block its workers plan with (``...``: none handed, looked up)."""
    from pipelines.loop.mpc_setup import mpc_config

    spec = cell.spec.behind(cell.world.sensor_range, cell.world.sensor_tracks)  # as the worker builds it
    horizon = mpc_config(spec, world=cell.world.env_config().world()).horizon
    at = ... if handed is ... else None if handed is None else handed.located()
    return margins_planned(spec.margins, spec.predictor_name, horizon, blocks, at)


def margins_planned(
    margins: MarginSpec,
    predictor: str | None,
    horizon: int,
    blocks: Callable[[], InForce] | None = None,
    at: Located | None | EllipsisType = ...,
) -> dict[str, Any]:
    """What ``margins`` plan with now for the zoo's ``predictor`` at ``horizon``, in ``planned_margins``'
    form: a resume checks a cell's records against it, and `config show --from-sweep` a remade
    calibration's. ``blocks``: the calibration blocks in force, as ``margins_read.read_once`` read them for
    every cell (None: read here); ``at``: the block the cell's workers plan with (``...``: looked up here)."""
    from pipelines.loop.margins import CALIBRATED_MODES
    from predictors.registry import checkpoint_sha256

    sha256 = None  # a block handed (``at``) is the weights' the sweep checked: no manifest read for it
    if at is ...:
        sha256 = checkpoint_sha256(predictor)
        read = blocks() if blocks is not None and margins.mode in CALIBRATED_MODES else None
        at = margins.located(predictor, horizon, sha256, read)  # read once, as the controller does
    classes = margins.resolve_classes(predictor, horizon, sha256, at)
    planned = {
        "margins_m": list(margins.resolve(predictor, horizon, sha256, at)),
        "classes": None if classes is None else _planned_classes(classes.to_json()),
    }
    return json.loads(json.dumps(plain(planned)))  # as read back from a record


def stored_margins(record: dict[str, Any] | None) -> dict[str, Any] | None:
    """What ``record`` says its episode planned with, in ``planned_margins``' form; None: it says nothing."""
    config = record.get("config") if record is not None else None
    margins = config.get("margins") if isinstance(config, dict) else None
    if not isinstance(margins, dict) or "margins_m" not in margins:  # a controller that plans with none
        return None
    return {"margins_m": margins.get("margins_m"), "classes": _planned_classes(margins.get("classes"))}


def _planned_classes(classes: Any) -> Any:
    """Recorded margins per motion class less their sample counts: the controller plans with the classes'
    edges and margins alone, and a recalibration that moved a count and no margin plans the same episodes
    (constant_velocity's block remade after a63500e: 2 more standing samples at k = 1, every margin equal,
    100 of 100 safe-configuration episodes equal), which a resume and --reuse refused as "other motion
    classes"."""
    if not isinstance(classes, dict):
        return classes
    return {key: value for key, value in classes.items() if key != "n"}
