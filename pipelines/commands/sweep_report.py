"""``crowdmpc sweep``'s report: the table and plots of what a sweep directory holds, after a run or on its
own (``--report-only``), and the CPU time the planned episodes take. How a run went is ``sweep_run``'s; what
the report reads of the log, ``sweep_log_read``'s; the notes under its table, ``sweep_table_notes``'.

``--report-only`` tabulates the sweep that is in ``--out``: its experiment is sweep.json's (another would
label the records as that experiment's methods, since cell keys do not name the experiment), and the crowd
sizes, team size and seed the command line leaves out are those the sweep's last run recorded, so that the
plan matches the records; a plan that matches none of them is refused rather than written over the report
as empty tables.
"""

from __future__ import annotations

import dataclasses
import shlex
import sys
from typing import TYPE_CHECKING, Any

from pipelines.commands.sweep_log_read import episode_rows, read_log
from pipelines.commands.sweep_table_notes import code_note, not_counted_note
from pipelines.errors import PipelineError, print_note
from predictors.text_table import counted

if TYPE_CHECKING:
    from pipelines.commands.sweep_log_read import LogRead
    from pipelines.config import RunConfig
    from pipelines.experiments.sweep_config import SweepConfig
    from pipelines.experiments.tasks import Cell, EpisodeTask


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
    workers: int | None = None,
) -> None:
    """Tabulates the planned episodes recorded in --out and projects the plan's CPU time. With
    ``report_only``, records none of which the plan holds are refused (the report is left as it was).
    ``log``: what the sweep read and appended of the log (``LogRead.of_plan`` fed by ``run_sweep``), else
    the log is read here. ``workers``: the episodes the run's backend ran at once (``run_cells``), which the
    projection divides by; None (no run, or a backend that did not say): those ``config`` asks for."""
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
    _write(config, cells, tasks, log, workers)
    changed = "" if zoo is None else zoo.note()
    if changed:
        print_note(f"note: {changed}")


def _note_unrun_cells(cells: tuple[Cell, ...], recorded: set[str]) -> None:
    """Say which planned cells --out holds no episode of (``recorded``: the cells of its planned records):
    the table leaves their columns out, so a value added to --vary (or a crowd size to --humans) and
    reported before it ran vanished without a word."""
    unrun = [f"{c.method!r} ({counted(c.n_humans, 'human')})" for c in cells if c.key not in recorded]
    if unrun:
        print_note(
            f"note: --report-only: no episode of {len(unrun)} planned cells, left out of the table: "
            f"{', '.join(unrun)}; run the sweep without --report-only to run them"
        )


def report_stopped(
    config: SweepConfig,
    cells: tuple[Cell, ...],
    tasks: list[EpisodeTask],
    log: LogRead | None = None,
    workers: int | None = None,
) -> None:
    """The report of a sweep that stopped itself part way (SweepStopped): what it recorded stands. None when
    the plan has no record yet (a sweep stopped before its first). ``log``, ``workers``: as ``report``'s (the
    stop's ``workers``: a Ray cluster's stop projected for the --workers asked, not the actors that fit)."""
    log = read_log(config, cells, tasks) if log is None else log
    if log.planned:
        _write(config, cells, tasks, log, workers)


def _write(
    config: SweepConfig,
    cells: tuple[Cell, ...],
    tasks: list[EpisodeTask],
    log: LogRead,
    workers: int | None = None,
) -> None:
    from pipelines.experiments.log import EPISODES_FILE
    from pipelines.experiments.report import write_report_of
    from pipelines.experiments.summary import summarize_columns

    summaries = summarize_columns(config.experiment, cells, log.columns)
    rows = episode_rows(config.out / EPISODES_FILE, cells, log, config.progress)
    note = not_counted_note(cells, tasks, {s.cell.key: s.episodes for s in summaries})
    note = "\n\n".join(line for line in (note, code_note(config.out, log.runs)) if line)
    report = write_report_of(config.out, config.experiment, summaries, rows, note)
    print(report.markdown)
    print_note("wrote " + ", ".join(str(p) for p in report.files))
    cpu = [log.cpu[i] for i in range(len(log.cpu))]
    if cpu:
        # CPU time, unlike wall time, does not depend on what else runs on the machine: an honest projection.
        mean = sum(cpu) / len(cpu)
        total = mean * len(tasks)
        # the workers the run's backend started (a Ray cluster may fit fewer than asked: ray_join's
        # workers_that_fit), else those the sweep asks for; inline runs one episode at a time
        k = workers or (1 if config.backend == "inline" else config.workers)
        running = f"{counted(k, 'worker')} on {counted(k, 'free core')}"
        print(
            f"CPU per episode {mean:.2f} s (mean of {len(cpu)}); the {len(tasks)} planned episodes take "
            f"{duration(total)} of CPU: {duration(total / k)} for {running}",
            file=sys.stderr,
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
