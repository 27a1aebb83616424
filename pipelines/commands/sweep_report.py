"""``crowdmpc sweep``'s report: how a run went (``run_cells``), the table and plots of what a sweep directory
holds, after a run or on its own (``--report-only``), and the CPU time the planned episodes take.

``--report-only`` tabulates the sweep that is in ``--out``: its experiment is sweep.json's (another would
label the records as that experiment's methods, since cell keys do not name the experiment), and the crowd
sizes, team size and seed the command line leaves out are those the sweep's last run recorded, so that the
plan matches the records; a plan that matches none of them is refused rather than written over the report
as empty tables.
"""

from __future__ import annotations

import dataclasses
import json
import shlex
import sys
import zlib
from collections import Counter
from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipelines.errors import EPISODES_RAISED, PipelineError
from pipelines.experiments.cell_columns import FLOATS, CellColumns, Column
from pipelines.experiments.run_lines import run_number, runs_named
from predictors.text_table import counted

if TYPE_CHECKING:
    from pipelines.config import RunConfig
    from pipelines.experiments.sweep_config import SweepConfig
    from pipelines.experiments.tasks import Cell, EpisodeTask


# a sweep stopped by Ctrl-C or SIGTERM; it exits with stop_status() (143 for SIGTERM: loop.interrupt)
INTERRUPTED = 130


def recorded_plan(cfg: RunConfig, config: SweepConfig) -> SweepConfig:
    """``config`` for ``--report-only``: refused when ``--out`` holds a sweep of another experiment, and
    with the humans, robots, seed and episodes per cell the run did not give (option, config file or
    --set) taken from the sweep's last run line in sweep.json. A directory without sweep.json keeps
    ``config`` as it is."""
    from pipelines.experiments.log import SWEEP_FILE, read_sweep_file
    from pipelines.experiments.run_lines import is_reused

    path = config.out / SWEEP_FILE
    if not path.is_file():
        return config
    meta = read_sweep_file(path)
    recorded = meta.get("experiment")
    if recorded is not None and recorded != config.experiment.name:
        from pipelines.experiments.cells import experiment_option

        raise PipelineError(
            f"--report-only: {config.out} holds a sweep of experiment {recorded!r}, not "
            f"{config.experiment.name!r} (its records would be tabulated as that experiment's methods); "
            + experiment_option(recorded)
        )
    # the sweep's own runs: a line --reuse copied is another experiment's (pipelines.experiments.reuse)
    runs = [run for run in meta.get("runs", []) if isinstance(run, dict) and not is_reused(run)]
    if not runs:
        return config
    last = runs[-1]
    changes: dict[str, Any] = {}
    humans = last.get("humans")
    # not chosen: a config file written by `config show` states every default, and asks for none of them
    if not cfg.chosen("sweep", "humans") and isinstance(humans, list) and humans:
        if all(_is_int(h) for h in humans):
            changes["humans"] = tuple(humans)
    for section, key, field in (
        ("sweep", "seed", "seed"),
        ("scenario", "robots", "n_robots"),
        ("sweep", "episodes_per_cell", "episodes_per_cell"),  # the CPU projection is of the run's plan
    ):
        value = last.get(field)  # a run line names them as SweepConfig does
        if not cfg.chosen(section, key) and _is_int(value):
            changes[field] = value
    return dataclasses.replace(config, **changes)


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def report(
    config: SweepConfig,
    cells: tuple[Cell, ...],
    tasks: list[EpisodeTask],
    *,
    report_only: bool = False,
    log: LogRead | None = None,
) -> None:
    """Tabulates the planned episodes recorded in --out and projects the plan's CPU time. With
    ``report_only``, records none of which the plan holds are refused (the report is left as it was).
    ``log``: what the sweep read and appended of the log (``LogRead.of_plan`` fed by ``run_sweep``), else
    the log is read here."""
    from pipelines.experiments.log import EPISODES_FILE
    from pipelines.experiments.zoo_changes import ZooChanges

    # a report of an old folder says when a rerun would plan otherwise, as `config show --from-sweep` does,
    # from the records it reads anyway (the report's files are of the records, and stay as they were)
    zoo = ZooChanges() if report_only and log is None else None
    log = read_log(config, cells, tasks, None if zoo is None else zoo.add) if log is None else log
    if report_only and log.held and not log.planned:
        out, held = config.out, log.held
        humans = ",".join(map(str, config.humans or config.experiment.humans))
        methods = ", ".join(label for label, _ in config.experiment.methods)
        raise PipelineError(
            f"--report-only: {out / EPISODES_FILE} holds {held} records, none of them of the cells planned "
            f"here (experiment {config.experiment.name}, --humans {humans}, --robots {config.n_robots}, "
            f"--seed {config.seed}, methods {methods}); the report is left as it was: give the options the "
            f"sweep ran with (`crowdmpc config show --from-sweep {shlex.quote(str(out))}` prints them)"
        )
    if report_only:
        _note_unrun_cells(cells, log.cells)
    _write(config, cells, tasks, log)
    changed = "" if zoo is None else zoo.note()
    if changed:
        print(f"note: {changed}", file=sys.stderr)


def _note_unrun_cells(cells: tuple[Cell, ...], recorded: set[str]) -> None:
    """Say which planned cells --out holds no episode of (``recorded``: the cells of its planned records):
    the table leaves their columns out, so a value added to --vary (or a crowd size to --humans) and
    reported before it ran vanished without a word."""
    unrun = [f"{c.method!r} ({counted(c.n_humans, 'human')})" for c in cells if c.key not in recorded]
    if unrun:
        print(
            f"note: --report-only: no episode of {len(unrun)} planned cells, left out of the table: "
            f"{', '.join(unrun)}; run the sweep without --report-only to run them",
            file=sys.stderr,
        )


def report_stopped(
    config: SweepConfig, cells: tuple[Cell, ...], tasks: list[EpisodeTask], log: LogRead | None = None
) -> None:
    """The report of a sweep that stopped itself part way (SweepStopped): what it recorded stands. None when
    the plan has no record yet (a sweep stopped before its first). ``log``: as ``report``'s."""
    log = read_log(config, cells, tasks) if log is None else log
    if log.planned:
        _write(config, cells, tasks, log)


@dataclass
class LogRead:
    """What the report takes of a sweep's log, read a record at a time: a report that held every record
    (its config left out) held 3.7 KB an episode, 4.1 GB at a million (benchmarks/sweep_log_scale.py)."""

    held: int = 0  # records in the log
    planned: int = 0  # of those, the plan's episodes
    cells: set[str] = dataclasses.field(default_factory=set)  # the cells of those
    # of the plan's episodes of ``cells``' cells (those the report tabulates), by cell key
    columns: dict[str, CellColumns] = dataclasses.field(default_factory=dict)
    cpu: Column = dataclasses.field(
        default_factory=lambda: Column(FLOATS)
    )  # each planned record's cpu_s that is set
    planned_keys: Collection[str] = ()  # the plan's episodes' keys
    tabulated: Collection[str] = ()  # the keys of the cells the report tabulates
    runs: set[int | None] = dataclasses.field(default_factory=set)  # the runs that made the tabulated ones

    @classmethod
    def of_plan(cls, cells: tuple[Cell, ...], tasks: list[EpisodeTask]) -> LogRead:
        """Nothing read yet, of the plan of ``tasks`` tabulated as ``cells``: ``add`` each record."""
        return cls(planned_keys={t.key for t in tasks}, tabulated={c.key for c in cells})

    def add(self, offset: int, line: bytes, record: dict[str, Any]) -> None:
        """The log's record ``record``, its line ``line`` at byte ``offset`` (``EpisodeLog.scan``'s)."""
        self.held += 1
        if record["key"] not in self.planned_keys:
            return
        self.planned += 1
        self.cells.add(record["cell"])
        if record.get("cpu_s") is not None:
            self.cpu.append(record["cpu_s"])
        if record["cell"] in self.tabulated:
            self.columns.setdefault(record["cell"], CellColumns()).add(record, offset, zlib.crc32(line))
            self.runs.add(run_number(record))


def read_log(
    config: SweepConfig,
    cells: tuple[Cell, ...],
    tasks: list[EpisodeTask],
    also: Callable[[dict[str, Any]], None] | None = None,
) -> LogRead:
    """--out's episodes.jsonl as the report reads it, checked as a sweep loads it; ``also``: given each
    record of the plan too (those the report is of)."""
    from pipelines.experiments.log import episode_log

    log = LogRead.of_plan(cells, tasks)
    for offset, line, record in episode_log(config.out).scan_shown(config.progress, repair=False):
        log.add(offset, line, record)
        if also is not None and record["key"] in log.planned_keys:
            also(record)
    return log


def episode_rows(
    path: Path, cells: tuple[Cell, ...], log: LogRead, progress: bool | None = False
) -> Iterator[dict[str, Any]]:
    """episodes.csv's rows, in the plan's order (report.episode_rows'), each made of its record read again
    from the log at its offset: a line that changed since (the log was replaced) is refused. ``progress``: a
    bar of the rows (None: on a terminal only), read again at ~25,000 a second, 40 s at a million."""
    from pipelines.experiments.report import episode_row
    from predictors.progress import progress_bar

    # each cell once, at its last place and with its last label, as report.episode_rows sorts and labels
    place = {c.key: i for i, c in enumerate(cells)}
    label = {c.key: c.method for c in cells}
    if not log.columns:  # no episode to read: a new sweep whose every episode raised has no log to open
        return
    total = sum(len(column) for column in log.columns.values())
    bar = progress_bar(
        total=total, show=progress, desc="writing episodes.csv", unit="ep", file=sys.stderr, leave=False
    )
    with open(path, "rb") as f, bar:
        for key in sorted(place, key=place.__getitem__):
            for offset, crc in log.columns[key].lines() if key in log.columns else ():
                f.seek(offset)
                line = f.readline()
                if zlib.crc32(line) != crc:
                    raise PipelineError(
                        f"{path} changed while the report read it (the record at byte {offset}); report again"
                    )
                bar.update(1)
                yield episode_row(json.loads(line), label[key])


def _write(config: SweepConfig, cells: tuple[Cell, ...], tasks: list[EpisodeTask], log: LogRead) -> None:
    from pipelines.experiments.log import EPISODES_FILE
    from pipelines.experiments.report import write_report_of
    from pipelines.experiments.summary import summarize_columns

    summaries = summarize_columns(config.experiment, cells, log.columns)
    rows = episode_rows(config.out / EPISODES_FILE, cells, log, config.progress)
    note = not_counted_note(cells, tasks, {s.cell.key: s.episodes for s in summaries})
    note = "\n\n".join(line for line in (note, code_note(config.out, log.runs)) if line)
    report = write_report_of(config.out, config.experiment, summaries, rows, note)
    print(report.markdown)
    print("wrote " + ", ".join(str(p) for p in report.files), file=sys.stderr)
    cpu = [log.cpu[i] for i in range(len(log.cpu))]
    if cpu:
        # CPU time, unlike wall time, does not depend on what else runs on the machine: an honest projection.
        mean = sum(cpu) / len(cpu)
        total = mean * len(tasks)
        k = 1 if config.backend == "inline" else config.workers  # inline runs one episode at a time
        workers = f"{k} worker{'s' if k > 1 else ''} on {k} free core{'s' if k > 1 else ''}"
        print(
            f"CPU per episode {mean:.2f} s (mean of {len(cpu)}); the {len(tasks)} planned episodes take "
            f"{duration(total)} of CPU: {duration(total / k)} for {workers}",
            file=sys.stderr,
        )


def code_note(out: Path, used: Collection[int | None] | None = None) -> str:
    """table.md's line naming the code behind its episodes, as sweep.json's runs recorded it: "Code: commit
    0123456789ab, crowdmpc 0.1.0, Python 3.11.7, CasADi 3.8.2, torch 2.13.0+cpu, numpy 2.4.6." (each
    version of the code once, in the order the runs met them); "" without a sweep.json. The table alone had
    said nothing of it, and a copy of it in a paper's supplement could not be traced to its code. ``used``:
    the runs (their records' ``run``) that made the tabulated episodes, whose code alone it names (every
    run's had named code that made none of them); None, or a record older than its run number: every run."""
    from pipelines.experiments.log import SWEEP_FILE, read_sweep_file

    if not (out / SWEEP_FILE).is_file():
        return ""
    runs = read_sweep_file(out / SWEEP_FILE).get("runs", [])
    runs = runs if used is None else runs_named(runs, used)
    shown = list(dict.fromkeys(_code_text(run) for run in runs))
    if len(shown) <= 1:
        return f"Code: {shown[0]}." if shown else ""
    return f"Code: {len(shown)} versions, in the order the sweep's runs used them: " + "; ".join(shown) + "."


def _code_text(run: Any) -> str:
    """A run line's recorded code (``pipelines.version.code_identity``, with its plugins) in one line; that
    of a run sweep.json no longer listed (``run_lines.lost_runs``) is unknown."""
    from pipelines.experiments.run_lines import is_lost, is_reused
    from pipelines.version import dirty_text

    if is_lost(run):  # a line --reuse took says which sweep's file lacks it
        return f"unknown ({run['lost']})" if is_reused(run) else "unknown (a run sweep.json no longer listed)"
    code = run.get("code") if isinstance(run, dict) else None
    if not isinstance(code, dict):
        return "not recorded (a run from before the code was)"
    parts = [f"commit {str(code.get('commit'))[:12]}{dirty_text(code.get('dirty'), code.get('diff_sha256'))}"]
    parts += [f"{label} {code[key]}" for key, label in _LIBRARIES if code.get(key)]
    plugins = code.get("plugins")
    if isinstance(plugins, dict):
        parts += [f"plugin {spec} {str(sha)[:12]}" for spec, sha in sorted(plugins.items())]
    return ", ".join(parts)


_LIBRARIES = (
    ("version", "crowdmpc"),
    ("python", "Python"),
    ("casadi", "CasADi"),
    ("torch", "torch"),
    ("numpy", "numpy"),
)

NOT_COUNTED_NAMED = 8  # cells named in table.md's note of episodes not recorded; the rest counted


def not_counted_note(cells: tuple[Cell, ...], tasks: list[EpisodeTask], recorded: dict[str, int]) -> str:
    """table.md's line for the tabulated cells with planned episodes not recorded ("" when none): an episode
    that raised or ran past --episode-timeout (errors.jsonl) is in no rate, so a cell whose slow episodes
    timed out had its rates of the quick ones, or no column at all, under "N episodes per cell"."""
    planned = Counter(task.cell.key for task in tasks)
    short = [
        f"{c.method} at {counted(c.n_humans, 'human')} "
        f"{planned[c.key] - recorded.get(c.key, 0)} of {planned[c.key]}"
        for c in cells
        if recorded.get(c.key, 0) < planned.get(c.key, 0)
    ]
    if not short:
        return ""
    if len(short) > NOT_COUNTED_NAMED:  # a sweep stopped early: every cell short
        short = [*short[:NOT_COUNTED_NAMED], f"{len(short) - NOT_COUNTED_NAMED} more cells"]
    return (
        f"Not counted, planned episodes not recorded: {'; '.join(short)} (each raised or ran past "
        "--episode-timeout, in errors.jsonl, or has not run yet; a rerun runs them): the rates are of the "
        "recorded episodes, and a cell with none has no column."
    )


def duration(seconds: float) -> str:
    """``seconds`` in the unit that reads best: "42.0 s", "3.5 min", "2.25 h", "12.5 days". The unit is
    chosen on the rounded figure, so 59.96 s reads "1.0 min", not "60.0 s"."""
    if round(seconds, 1) < 60:
        return f"{seconds:.1f} s"
    if round(seconds / 60, 1) < 60:
        return f"{seconds / 60:.1f} min"
    if round(seconds / 3600, 2) < 48:
        return f"{seconds / 3600:.2f} h"
    return f"{seconds / 86400:.1f} days"


def _note_retried(config: SweepConfig) -> None:
    """Say that the plan's episodes errors.jsonl lists have been recorded since: a folder complete after its
    retries kept their entries with nothing marking them retried, as if they still failed."""
    from pipelines.experiments.log import ERRORS_FILE, error_keys

    retried = error_keys(config.out) & {t.key for t in config.tasks()}
    if retried:
        print(
            f"note: {config.out / ERRORS_FILE} lists {len(retried)} episode(s) of this plan that raised in "
            "an earlier run; each is recorded since (the file keeps their tracebacks)",
            file=sys.stderr,
        )


def _recorded(config: SweepConfig) -> int:
    """The plan's episodes --out's log holds, read again."""
    from pipelines.experiments.log import episode_log

    planned = {t.key for t in config.tasks()}
    return sum(record["key"] in planned for _, _, record in episode_log(config.out).scan(repair=False))


def run_cells(
    config: SweepConfig, log: LogRead | None = None, weights: Mapping[str, str | None] | None = None
) -> int:
    """Runs the episodes not yet recorded and says how it went; returns the exit status (EPISODES_RAISED: some
    episodes raised, INTERRUPTED). ``log``: given every record of the log, those held and those this run
    appends; ``weights``: ``run_sweep``'s, the weights the plan's checks loaded."""
    from pipelines.experiments.sweep import run_sweep

    status = 0
    outcome = run_sweep(config, records=None if log is None else log.add, weights=weights)
    if outcome.interrupted:  # the log's own count: a SIGTERM between a record's append and its count
        outcome.ran = _recorded(config) - outcome.already_done
    done = outcome.already_done + outcome.ran
    rate = (
        f", {outcome.episodes_per_minute:.1f} episodes/min; "
        f"{outcome.steady_episodes_per_minute:.1f} after {outcome.startup_s:.1f} s of worker start-up"
        if outcome.ran
        else ""
    )
    print(
        f"{config.experiment.name}: {done}/{outcome.planned} episodes recorded ({outcome.ran} this run in "
        f"{outcome.wall_s:.0f} s{rate}, backend {outcome.backend or '-'})",
        file=sys.stderr,
    )
    if outcome.errors:
        raised = f"{len(outcome.errors)} episode{'' if len(outcome.errors) == 1 else 's'} raised"
        print(f"{raised}; see {config.out / 'errors.jsonl'} (a rerun retries)", file=sys.stderr)
        status = EPISODES_RAISED
    elif outcome.complete:
        _note_retried(config)
    if outcome.interrupted and done >= outcome.planned:  # after the last episode: nothing is left to resume
        print("interrupted after every planned episode was recorded: the report follows", file=sys.stderr)
        status = INTERRUPTED
    elif outcome.interrupted:  # no backend: stopped while it started (joining a cluster), before any episode
        again = "resume" if outcome.backend or outcome.already_done else "start it"
        why = "" if outcome.backend else " (stopped while its workers started: no episode ran this run)"
        print(f"interrupted: rerun the same command to {again}{why}", file=sys.stderr)
        status = INTERRUPTED
    return status
