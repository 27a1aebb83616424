"""Running an experiment's episodes in parallel, durably, resumably: the sweep's configuration and its driver.

The driver (``run_sweep``) plans the experiment's episodes, skips every one that ``<out>/episodes.jsonl``
already holds, hands the rest to a backend and writes each outcome as it comes back. Only the driver writes
the sweep directory: the records, the MCAP logs a worker kept (each before the record that vouches for it),
``<out>/errors.jsonl`` for the episodes that raised (a rerun tries them again, after the episodes never tried;
a run whose first new episodes all raise, before any runs, is misconfigured and stops), and
``<out>/sweep.json``, what the directory holds and a line per run (once its backend has started: a run
refused before it leaves none).

The parts, a module each: pipelines.experiments.log (the durable, resumable record log and the lock that
refuses a second sweep on the same directory), pipelines.experiments.worker (an episode run into a record,
with its MCAP log under ``--record``), pipelines.experiments.backends (where the workers run: Ray, a process
pool (pipelines.experiments.process_backend), or inline), pipelines.experiments.resume_checks (what a resumed
sweep's records must match: the predictor weights and margins its cells plan with now),
pipelines.experiments.outcome_write (an outcome written into the directory), pipelines.experiments.sweep_stop
(what a sweep that stops part way keeps of its other workers' episodes). The configuration,
``SweepConfig`` and its bounds, is pipelines.experiments.sweep_config; ``SweepConfig`` is importable from here
too, beside ``run_sweep`` (docs/examples/own_experiment.py).
"""

from __future__ import annotations

import functools
import sys
import time
from collections.abc import Callable, Collection, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Final

from pipelines.errors import PipelineError, SweepStopped, print_note
from pipelines.experiments.backends import Backend, check_backend, make_backend
from pipelines.experiments.checked_calibrations import Checked, checked_inputs, with_checked_calibrations
from pipelines.experiments.checked_weights import stopped_by, with_checked_weights
from pipelines.experiments.log import (
    ERRORS_FILE,
    SWEEP_FILE,
    EpisodeLog,
    episode_log,
    error_keys,
    read_sweep_file,
)
from pipelines.experiments.outcome_write import OutcomeWriter, local_time
from pipelines.experiments.resume_checks import read_recorded
from pipelines.experiments.reuse import check_source, seed_from
from pipelines.experiments.run_lines import lost_runs, split_lost, write_sweep_file
from pipelines.experiments.sweep_config import SweepConfig
from pipelines.experiments.sweep_folder import check_sweep_directory, sweep_lock
from pipelines.experiments.sweep_stop import keep_finished
from pipelines.experiments.tasks import EpisodeTask
from pipelines.experiments.worker import make_scratch_root, release_scratch_root
from pipelines.loop.interrupt import terminate_as_interrupt
from predictors.progress import progress_bar

# A sweep whose first episodes all raise is misconfigured (a missing model, a broken build): stop it rather
# than fill errors.jsonl with thousands of copies of one traceback. Only while this run has recorded none (a
# run extending a sweep too): once an episode succeeded the setup works, and those that raise fail alone.
FAIL_FAST_ERRORS: Final[int] = 4


@dataclass
class SweepOutcome:
    planned: int  # episodes the sweep asks for
    already_done: int  # of those, recorded before this run
    ran: int = 0  # recorded by this run
    errors: list[str] = field(default_factory=list)  # keys whose episode raised (see errors.jsonl)
    wall_s: float = 0.0  # this run, from starting the workers to the last record
    startup_s: float = 0.0  # of which starting the workers (processes, or Ray and its actors)
    backend: str = ""
    workers: int | None = None  # episodes the backend ran at once; None: none started, or it did not say
    interrupted: bool = False
    cut: int = 0  # at an interrupt, episodes in flight on the workers cut unrecorded (a resume runs them)
    unkept: str = ""  # at an interrupt, the line's tail: episodes back whose writing failed (sweep_stop)

    @property
    def complete(self) -> bool:
        return self.already_done + self.ran == self.planned

    @property
    def episodes_per_minute(self) -> float:
        """Over the whole run, worker start-up included."""
        return 60.0 * self.ran / self.wall_s if self.wall_s > 0 else 0.0

    @property
    def steady_episodes_per_minute(self) -> float:
        """Once the workers are up: the rate a long sweep approaches."""
        running = self.wall_s - self.startup_s
        return 60.0 * self.ran / running if running > 0 else 0.0


def sweep_meta(out: Path, config: SweepConfig) -> dict[str, Any]:
    """sweep.json's document (empty for a new sweep); PipelineError when it holds another experiment (a
    directory belongs to one). The dry run reads it so too, refusing what the run would."""
    path = out / SWEEP_FILE
    meta: dict[str, Any] = read_sweep_file(path) if path.exists() else {}
    if meta and meta.get("experiment") != config.experiment.name:
        raise PipelineError(
            f"{out} holds a sweep of experiment {meta.get('experiment')!r}, not {config.experiment.name!r}; "
            "choose another --out"
        )
    return meta


def _add_run(
    out: Path,
    meta: dict[str, Any],
    config: SweepConfig,
    planned: int,
    runs_recorded: set[int] | None,
    backend: str | None = None,
    *,
    last_run: int = 0,
) -> int:
    """Write sweep.json: ``meta`` with what the directory holds and a line for this run; return the run's
    number, counted from 1 as ``config show --from-sweep DIR --run N`` counts them (``runs[N - 1]``), which
    each record of the run keeps as its ``run``. ``backend``: the one that started (``--backend auto``
    names none), with Ray's version where it was Ray; None for a run with nothing to run."""
    from pipelines.plugins import code_with_plugins
    from pipelines.version import crowdmpc_version, library_version

    path = out / SWEEP_FILE
    meta["experiment"] = config.experiment.name
    meta["title"] = config.experiment.title
    runs = meta.setdefault("runs", [])
    runs.extend(lost_runs(out, len(runs), last_run))  # before this run's number is taken
    # a run that recorded no episode (stopped as its workers started) leaves no other code in the folder
    _note_other_code(out, [r for k, r in enumerate(runs, 1) if runs_recorded is None or k in runs_recorded])
    runs.append(
        {
            "started": local_time(),
            "version": crowdmpc_version(),
            "code": code_with_plugins(),
            "episodes_per_cell": config.episodes_per_cell,
            "humans": list(config.humans or config.experiment.humans),
            "seed": config.seed,
            "n_robots": config.n_robots,
            "jit": config.jit,
            "planned": planned,
            **({} if backend is None else {"backend": backend}),
            **({"ray": library_version("ray")} if backend == "ray" else {}),
            **({"config": config.run_config} if config.run_config is not None else {}),
            "cells": [
                {
                    "key": c.key,
                    "method": c.method,
                    "n_humans": c.n_humans,
                    "n_robots": c.n_robots,
                    **asdict(c.spec),
                    **asdict(c.world),
                }
                for c in config.experiment.cells(config.humans, config.n_robots)
            ],
        }
    )
    write_sweep_file(path, meta)
    return len(meta["runs"])


def _note_other_code(out: Path, runs: list[dict[str, Any]]) -> None:
    """Say so when an earlier run in the directory was made by other code (another commit, other libraries):
    its episodes are kept, and a table over both mixes two codebases. Not refused: a resume after a change
    that leaves results alone (documentation, a benchmark) is the common case. Uncommitted changes are
    recorded ("dirty") but cannot be compared, so they alone say nothing."""
    from pipelines.plugins import code_with_plugins
    from pipelines.version import code_changes

    # a run from before the code was recorded (4a16d16) has none: unknown, and results changed since
    kept, unknown = split_lost(runs)  # a lost run's code is unknown, not old: said apart
    shown = code_changes(
        (run.get("code") if isinstance(run, dict) else None for run in kept), code_with_plugins()
    )
    shown = "; ".join(filter(None, [shown, unknown]))
    if shown:  # every resume says it, not only the first after the change: the mix stays in the directory
        print_note(
            f"note: {out} holds episodes made by other code ({shown}); they are kept, and a table of cells "
            "holding both mixes them (table.md's Code line names what it tabulates; a new --out keeps one "
            "codebase per table)"
        )


def run_sweep(
    config: SweepConfig,
    *,
    backend_factory: Callable[[SweepConfig, str], Backend] | None = None,
    records: Callable[[int, bytes, dict[str, Any]], None] | None = None,
    weights: Mapping[str, str | None] | None = None,
    calibrations: Checked | None = None,
) -> SweepOutcome:
    """Run every planned episode that ``<out>/episodes.jsonl`` does not hold yet.

    ``backend_factory(config, scratch_root)``: the backend (default: ``config``'s); ``scratch_root`` is this
    run's folder for the workers' temporary files, which the driver removes when the run ends (and the next
    sweep removes when the driver was killed, pipelines.experiments.worker). ``records(offset, line,
    record)``: called with each record of the log as ``EpisodeLog.scan`` gives it, those it held as the
    resume reads them, then each this run appends (read back from its line): the report of the run
    (``crowdmpc sweep``) needs not read the log again. ``weights``: the sha256 of each zoo predictor's weights
    as the caller checked them (``crowdmpc sweep``: check_plan's loads), which every worker's load must
    match (pipelines.experiments.checked_weights; None: the zoo's manifests' as the run starts); alike
    ``calibrations``, each method's calibration block (pipelines.experiments.checked_calibrations)."""
    _refuse_in_worker_start()
    out = Path(config.out)
    if backend_factory is None:  # a choice refused here leaves no folder, nor a line in sweep.json
        check_backend(config.backend, config.workers, config.ray_address)
    check_sweep_directory(out)
    if config.reuse is not None:  # a source that is no sweep leaves no --out made
        check_source(config.reuse, out)
    made = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    tasks = config.tasks()
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        raise PipelineError("the sweep plans the same episode twice (repeated --humans?)")
    with sweep_lock(out, made):
        meta = sweep_meta(out, config)
        checked = checked_inputs(tasks, weights, calibrations)
        if config.reuse is not None:  # its run lines and records, checked against what the workers are handed
            meta = seed_from(config.reuse, out, config.experiment, tasks, meta, config.progress, checked)
        log = episode_log(out)
        recorded = read_recorded(out, tasks, config.progress, repair=True, records=records, checked=checked)
        note = recorded.outside_note()
        if note is not None:
            print_note(note)
        # A refused resume is no run, nor a backend that could not start: the run's line is added once the
        # backend has started (an interrupted run is recorded), or at once when there is nothing to run.
        add_run = functools.partial(
            _add_run, out, meta, config, len(tasks), recorded.runs_recorded, last_run=recorded.last_run
        )
        # Episodes that raised before (errors.jsonl) last: a rerun that extends the sweep runs the new ones
        # first, rather than stopping on the same failures again.
        retried = error_keys(out)
        left = [t for i, t in enumerate(tasks) if not recorded.recorded(i)]
        todo = [t for t in left if t.key not in retried] + [t for t in left if t.key in retried]
        outcome = SweepOutcome(planned=len(tasks), already_done=len(tasks) - len(todo))
        if not todo:
            add_run()
            return outcome
        todo = with_checked_calibrations(with_checked_weights(todo, checked.weights), checked.calibrations)
        scratch = make_scratch_root()
        try:
            with terminate_as_interrupt():
                factory = backend_factory or _default_backend
                _run_tasks(
                    config,
                    todo,
                    log,
                    outcome,
                    factory,
                    str(scratch),
                    retried,
                    started=add_run,
                    records=records,
                )
        except KeyboardInterrupt:
            outcome.interrupted = True
        finally:
            release_scratch_root(scratch)
    return outcome


def _refuse_in_worker_start() -> None:
    """A process pool's worker imports the driver's main script as it starts (multiprocessing's spawn, the
    pool's start method on every OS): a script that calls run_sweep outside ``if __name__ == "__main__":``
    calls it again there, and each worker failed on the driver's lock of --out, "another sweep is writing
    to ...", which sent the user looking for a sweep that was not there."""
    import multiprocessing

    # what multiprocessing's own check (spawn._check_not_importing_main) reads: set while a child imports
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        raise PipelineError(
            "run_sweep was called while a sweep worker process started: each one imports the script that "
            'runs the sweep first; call run_sweep under if __name__ == "__main__": (as '
            "docs/examples/own_experiment.py does)"
        )


def _run_tasks(
    config: SweepConfig,
    todo: list[EpisodeTask],
    log: EpisodeLog,
    outcome: SweepOutcome,
    backend_factory: Callable[[SweepConfig, str], Backend],
    scratch: str,
    retried: Collection[str],
    started: Callable[[str], int],
    records: Callable[[int, bytes, dict[str, Any]], None] | None,
) -> None:
    """Start the backend, call ``started`` with its name (the run's line in sweep.json: a backend that could
    not start ran nothing; it returns the run's number), write every outcome as it comes back, each record
    with that number as its ``run``, and end the backend. Stop (SweepStopped) when no episode has run and
    FAIL_FAST_ERRORS episodes not ``retried`` (keys that raised in an earlier run) have raised: a broken
    method or setting, also when it extends a sweep; old failures raising again tell nothing new, and run
    after the new episodes. Stop too at a worker's ``stop`` (weights replaced since the driver checked them):
    every later episode of that predictor met it, one error each. At a stop, an interrupt's too, the episodes
    the other workers hand back within a bound are written first (pipelines.experiments.sweep_stop), and the
    SweepStopped carries the workers the backend ran at once, for the report's projection."""
    out = Path(config.out)
    by_key = {t.key: t for t in todo}
    start = time.perf_counter()
    backend = backend_factory(config, scratch)
    outcome.backend = backend.name
    outcome.workers = getattr(backend, "workers", None)  # a backend of one's own may not say
    outcome.startup_s = time.perf_counter() - start
    bar: Any = None
    try:
        run = started(backend.name)
        bar = _progress_bar(config, outcome)
        keep = OutcomeWriter(log, outcome, by_key, run, records, bar, backend.name)
        refusal: str | None = None  # a worker's stop
        try:
            for result in backend.run(todo):
                if result.stop is not None:  # not written to errors.jsonl: no episode of it ran
                    refusal = result.stop
                    break
                keep(result)
                if result.error is not None and outcome.ran == 0:
                    _fail_fast(outcome, retried, result.error, out)
        except SweepStopped as stopped:  # the backend's (a lost cluster, dying workers) or _fail_fast's
            # what the other workers finished is written first (pipelines.experiments.sweep_stop)
            kept = keep_finished(backend, keep)
            raise SweepStopped(f"{stopped}{kept.note()}", outcome.workers) from None
        except KeyboardInterrupt:  # Ctrl-C, SIGTERM: a stop too; a second one ends the wait at once
            kept = keep_finished(backend, keep, functools.partial(bar.write, file=sys.stderr))
            outcome.cut, outcome.unkept = kept.cut, kept.unkept
            raise
        if refusal is not None:
            kept = keep_finished(backend, keep)  # before the count of the episodes recorded
            recorded = outcome.already_done + outcome.ran
            raise SweepStopped(stopped_by(refusal, recorded, out) + kept.note(), outcome.workers)
    finally:
        outcome.wall_s = time.perf_counter() - start
        if bar is not None:
            bar.close()
        backend.close()


def _fail_fast(outcome: SweepOutcome, retried: Collection[str], error: str, out: Path) -> None:
    """SweepStopped once FAIL_FAST_ERRORS episodes not ``retried`` have raised, none recorded yet."""
    if sum(key not in retried for key in outcome.errors) >= FAIL_FAST_ERRORS:
        last = error.strip().splitlines()[-1]
        raise SweepStopped(
            f"the first {len(outcome.errors)} episodes all raised ({last}); tracebacks in {out / ERRORS_FILE}"
        )


def _default_backend(config: SweepConfig, scratch: str) -> Backend:
    return make_backend(
        config.backend,
        config.workers,
        config.record,
        config.ray_address,
        config.jit,
        scratch,
        config.episode_timeout_s,
    )


def _progress_bar(config: SweepConfig, outcome: SweepOutcome) -> Any:
    return progress_bar(
        total=outcome.planned,
        initial=outcome.already_done,
        unit="ep",
        desc=config.experiment.name,
        show=config.progress,
        file=sys.stderr,
        dynamic_ncols=True,
        smoothing=0.05,  # episodes vary in length: average the rate over many for a steady ETA
    )
