"""How a ``crowdmpc sweep`` run went (``run_cells``): the episodes it ran, those that raised, and what to
do after an interrupt, with the exit status that says it."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

from pipelines.errors import EPISODES_RAISED, print_note

if TYPE_CHECKING:
    from pipelines.commands.sweep_log_read import LogRead
    from pipelines.commands.sweep_predictors import PlanModels
    from pipelines.experiments.sweep_config import SweepConfig

# a sweep stopped by Ctrl-C or SIGTERM; it exits with stop_status() (143 for SIGTERM: loop.interrupt)
INTERRUPTED = 130


def _note_retried(config: SweepConfig) -> None:
    """Say that the plan's episodes errors.jsonl lists have been recorded since: a folder complete after its
    retries kept their entries with nothing marking them retried, as if they still failed."""
    from pipelines.experiments.log import ERRORS_FILE, error_keys

    retried = error_keys(config.out) & {t.key for t in config.tasks()}
    if retried:
        print_note(
            f"note: {config.out / ERRORS_FILE} lists {len(retried)} episode(s) of this plan that raised in "
            "an earlier run; each is recorded since (the file keeps their tracebacks)"
        )


def _recorded(config: SweepConfig) -> int:
    """The plan's episodes --out's log holds, read again."""
    from pipelines.experiments.log import episode_log

    planned = {t.key for t in config.tasks()}
    return sum(record["key"] in planned for _, _, record in episode_log(config.out).scan(repair=False))


def run_cells(
    config: SweepConfig, log: LogRead | None = None, models: PlanModels | None = None
) -> tuple[int, int | None]:
    """Runs the episodes not yet recorded and says how it went; returns the exit status (EPISODES_RAISED: some
    episodes raised, INTERRUPTED) and the episodes the backend ran at once (None: none started, or it did not
    say): a Ray cluster may fit fewer than --workers, and the report's CPU projection divides by these.
    ``log``: given every record of the log, those held and those this run appends; ``models``: the plan's
    checks' reads, whose weights and calibration blocks the workers take."""
    from pipelines.experiments.sweep import run_sweep
    from pipelines.experiments.sweep_stop import cut_note

    status, records = 0, None if log is None else log.add
    weights, blocks = (None, None) if models is None else (models.weights(), models.calibrations())
    outcome = run_sweep(config, records=records, weights=weights, calibrations=blocks)
    if outcome.interrupted:  # the log's own count: a SIGTERM between a record's append and its count
        outcome.ran = _recorded(config) - outcome.already_done
    done = outcome.already_done + outcome.ran
    rate = (
        f", {outcome.episodes_per_minute:.1f} episodes/min; "
        f"{outcome.steady_episodes_per_minute:.1f} after {outcome.startup_s:.1f} s of worker start-up"
        if outcome.ran
        else ""
    )
    print_note(
        f"{config.experiment.name}: {done}/{outcome.planned} episodes recorded ({outcome.ran} this run in "
        f"{outcome.wall_s:.0f} s{rate}, backend {outcome.backend or '-'})"
    )
    if outcome.errors:
        raised = f"{len(outcome.errors)} episode{'' if len(outcome.errors) == 1 else 's'} raised"
        print_note(f"{raised}; see {config.out / 'errors.jsonl'} (a rerun retries)")
        status = EPISODES_RAISED
    elif outcome.complete:
        _note_retried(config)
    if outcome.interrupted and done >= outcome.planned:  # after the last episode: nothing is left to resume
        print("interrupted after every planned episode was recorded: the report follows", file=sys.stderr)
        status = INTERRUPTED
    elif outcome.interrupted:  # no backend: stopped while it started (joining a cluster), before any episode
        again = "resume" if outcome.backend or outcome.already_done else "start it"
        why = "" if outcome.backend else " (stopped while its workers started: no episode ran this run)"
        print_note(
            f"interrupted: rerun the same command to {again}{why}{cut_note(outcome.cut)}{outcome.unkept}"
        )
        status = INTERRUPTED
    return status, outcome.workers
