"""The process pool's backend: K spawned processes of a ``concurrent.futures`` pool run the sweep's episodes
(pipelines.experiments.backends picks it when Ray is not installed, or for ``--backend process``).

What it holds: the pool's workers (one EpisodeWorker each, ignoring Ctrl-C, holding a SIGTERM or SIGHUP until
the driver ends them (pool_stop), exiting with a killed driver), the environment they start with (pool_spawn),
the resource tracker started (pool_tracker), and the break handling: a worker process that dies breaks the
whole pool, each episode in flight becomes an episode error, a new pool runs the rest, and the sweep stops
(SweepStopped) when the pool keeps breaking with nothing finishing."""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, Any, Final

from pipelines.errors import PipelineError, SweepStopped, quiet_team_warnings, warnings_as_notes
from pipelines.experiments.pool_spawn import child_environment, children_ignore_sigint
from pipelines.experiments.pool_stop import PoolStop, hold_stop_signals, run_unless_stopped, take_part
from pipelines.experiments.pool_tracker import start_resource_tracker
from pipelines.experiments.tasks import EpisodeTask
from pipelines.experiments.worker import (
    SINGLE_THREAD_ENV,
    EpisodeOutcome,
    EpisodeWorker,
    make_scratch_root,
    release_scratch_root,
    worker_scratch,
)
from predictors.plugin_import import search_listed_folders

if TYPE_CHECKING:
    from concurrent.futures import Future


# Times a process pool may break (a worker process died) with no episode finishing in between before the sweep
# stops: every episode then kills its worker, and each new pool costs seconds to start.
MAX_BREAKS_IN_A_ROW: Final[int] = 3
BROKEN_POOL_WAIT_S: Final[float] = 30.0  # for the futures of a broken pool to fail (they do at once)
STARTING_EXIT_S: Final[float] = 5.0  # for workers that died starting to finish exiting (they do at once)
CLOSE_GRACE_S: Final[float] = 10.0  # for idle workers to close their controllers and exit at a sweep's end

_WORKER: EpisodeWorker | None = None  # one per pool process


def _exit_with_parent() -> None:
    """A pool worker whose driver was killed (SIGKILL leaves no time to shut the pool down) exits at once
    instead of finishing its episode and waiting for work forever."""
    import multiprocessing
    from multiprocessing.connection import wait

    parent = multiprocessing.parent_process()
    if parent is None:
        return

    def watch() -> None:
        wait([parent.sentinel])
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="exit-with-parent").start()


def _init_pool_worker(
    record: str, jit: bool, scratch_root: str | None, timeout_s: float | None, stop: Any
) -> None:
    import multiprocessing.util
    import signal

    global _WORKER
    take_part(stop)  # the pool's PoolStop.shared
    hold_stop_signals()  # a SIGTERM or SIGHUP to the sweep's process group: the episode running goes on
    # Ctrl-C goes to the whole process group; the driver alone handles it (and ends the workers).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _exit_with_parent()
    warnings_as_notes()  # as the driver shows them
    quiet_team_warnings()  # for the worker's life: the sweep says them once (sweep_checks.method_notes)
    search_listed_folders()  # the driver's plugin folders, before the move below
    scratch = worker_scratch(scratch_root)
    if jit:  # CasADi's jit writes its C sources into the current directory (no option for another)
        os.chdir(scratch)
    _load_plugins()
    _WORKER = EpisodeWorker(record, jit, scratch, timeout_s)
    # its controllers closed when the worker exits after the pool's last task (ProcessBackend.close lets it)
    multiprocessing.util.Finalize(None, _WORKER.close, exitpriority=10)


def _load_plugins() -> None:
    """The plugins the driver's variables name, loaded as the driver loaded them: a net plugin loaded
    lazily, at the worker's first episode of it, left the recordings made before it naming no plugin, beside
    the later ones (``review``: "recorded by different code"). One that does not load here raises in the
    episodes that use it, with its message, not in the pool's start."""
    from pipelines.plugins import PluginError, load_environment_plugins

    with contextlib.suppress(PluginError):
        load_environment_plugins()


def _run_in_pool(task: EpisodeTask) -> EpisodeOutcome:
    assert _WORKER is not None, "pool worker used before its initializer ran"
    worker = _WORKER
    return run_unless_stopped(lambda: worker.run(task))


def _check_main_is_a_file() -> None:
    """Refuse a main script the spawned workers cannot read: each one runs the driver's ``__main__`` file
    again before anything else (multiprocessing.spawn's ``init_main_from_path``), and a script piped in
    (``python - < script.py``, ``__file__`` ``<stdin>``) is no file: every worker died of Python's own
    FileNotFoundError, and the one-line stop blamed a missing ``if __name__ == "__main__":``."""
    import sys

    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if main is None or getattr(main, "__spec__", None) is not None or path is None:
        return  # `python -m`, `-c`, a notebook: the workers import nothing from a path
    import multiprocessing.process

    # as spawn resolves it: from the folder this process started in (untyped in multiprocessing's stubs)
    where = os.path.join(getattr(multiprocessing.process, "ORIGINAL_DIR", None) or "", path)
    if not os.path.isfile(where):
        raise PipelineError(
            f"the sweep's worker processes run this program's main script {path!r} again as they start "
            "(multiprocessing's spawn), and it is no file they can read; run the script from a file, or "
            "sweep with backend 'inline'"
        )


def _worker_environment() -> dict[str, str]:
    """What the workers' environment holds beyond this process's: one library thread (unless the user set
    a variable of it), and every plugin registered here (pipelines.plugins.plugin_environment: spawned,
    they hold nothing this process imported)."""
    from pipelines.plugins import plugin_environment

    return {k: os.environ.get(k, v) for k, v in SINGLE_THREAD_ENV.items()} | plugin_environment()


class ProcessBackend:
    """K spawned processes of a concurrent.futures pool.

    A worker process that dies (a segfault in a library, the kernel's OOM killer, a plugin calling
    ``os._exit``) breaks the whole pool: every episode in flight then fails with ``BrokenProcessPool``, and
    which of them killed it cannot be told. Each of those becomes an episode error (errors.jsonl, retried by a
    rerun), a new pool takes the rest of the sweep, and the sweep stops when the pool breaks
    ``MAX_BREAKS_IN_A_ROW`` times with no episode finishing in between (every episode killing its worker)."""

    name = "process"

    def __init__(
        self,
        workers: int,
        record: str,
        jit: bool = False,
        scratch_root: str | None = None,
        timeout_s: float | None = None,
    ):
        """``scratch_root``: where the workers' scratch folders go (a sweep's); else the backend's own,
        removed on ``close`` or a failed start (a worker's own would stay: ``close`` ends it, no atexit)."""
        self.workers = workers
        _check_main_is_a_file()
        self._environment = _worker_environment()  # refuses a plugin the workers cannot import
        self._own_root = None if scratch_root is not None else make_scratch_root()
        root = scratch_root if self._own_root is None else str(self._own_root)
        self._initargs = (record, jit, root, timeout_s)
        start_resource_tracker()
        try:
            self._start_pool()
        except BaseException:  # a Ctrl-C while the workers start too: they end now, not when collected
            if getattr(self, "_pool", None) is not None:  # ended already after SweepStopped: a no-op
                self._end_pool()
            if self._own_root is not None:
                release_scratch_root(self._own_root)
            raise

    def _start_pool(self) -> None:
        """Start the pool's workers; SweepStopped when they die before taking any work."""
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor
        from concurrent.futures.process import BrokenProcessPool

        self._processes: list[Any] = []  # the pool's processes, kept: their exit codes say how they died
        context = multiprocessing.get_context("spawn")
        self._stop = PoolStop(context)  # a stop's word to the workers, and their count of episodes running
        with child_environment(self._environment), children_ignore_sigint():
            self._pool = ProcessPoolExecutor(
                max_workers=self.workers,
                mp_context=context,
                initializer=_init_pool_worker,
                initargs=(*self._initargs, self._stop.shared),
            )
            # Start every worker now (a spawn pool starts one in each submit), while the block is in force.
            started = [self._pool.submit(os.getpid) for _ in range(self.workers)]
        self._note_processes()
        try:
            for future in started:
                future.result()
        except BrokenProcessPool:
            # They are exiting: their own status, not the SIGTERM _end_pool sends one still alive (on a loaded
            # machine the pool breaks before the last has gone, and the message read "ended abruptly").
            for process in self._processes:
                process.join(timeout=STARTING_EXIT_S)
            self._end_pool()  # every process joined: their exit codes are known
            raise SweepStopped(self._died_starting()) from None
        self._pool_ended = False
        self._drained = False
        self._in_flight: dict[Future[EpisodeOutcome], EpisodeTask] = {}  # the run's (``run``, ``finished``)

    def _died_starting(self) -> str:
        """Why no worker started. Each spawned worker imports the driver's main script before anything else:
        a script that calls run_sweep outside ``if __name__ == "__main__":`` calls it again in every worker,
        where it failed on the driver's lock of --out ("another sweep is writing to ..."), and the driver
        ended in a BrokenProcessPool traceback."""
        return (
            f"the worker processes ended as they started, before any episode ({self._deaths()}); their "
            "messages are above. A script that runs a sweep must do so under "
            'if __name__ == "__main__": (every worker process imports it first: multiprocessing\'s spawn)'
        )

    def _note_processes(self) -> None:
        """Add the processes in the pool's table now (it may start one for a task) to ``_processes``: the
        table is gone once the pool shuts down."""
        current = (getattr(self._pool, "_processes", None) or {}).values()
        self._processes += [p for p in current if p not in self._processes]

    def run(self, tasks: Iterable[EpisodeTask]) -> Iterator[EpisodeOutcome]:
        from concurrent.futures import FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        self._drained = False  # until this run's episodes have all come back
        pending = iter(tasks)
        unsent: list[EpisodeTask] = []  # taken from ``pending`` but refused by a pool that broke meanwhile
        # handed to the pool, not yielded yet: ``finished`` takes them at a stop
        in_flight = self._in_flight = {}
        breaks = 0  # pool breaks since an episode last came back
        while True:
            broken = self._submit(in_flight, unsent, pending)
            if not in_flight and not broken:
                self._drained = True  # every episode came back: close may let the workers exit of themselves
                return
            if not broken:
                done, _ = wait(in_flight, return_when=FIRST_COMPLETED)
                for future in done:
                    task = in_flight.pop(future)
                    try:
                        outcome = future.result()
                    except BrokenProcessPool:
                        in_flight[future] = task  # with the others lost in the break, below
                        broken = True
                        continue
                    breaks = 0
                    yield outcome
            if broken:
                outcomes, finished = self._lost(in_flight)
                breaks = 0 if finished else breaks + 1
                yield from outcomes
                if breaks >= MAX_BREAKS_IN_A_ROW:
                    raise SweepStopped(
                        f"the worker processes died {breaks} times in a row with no episode finishing in "
                        f"between ({self._deaths()}); the episodes lost are in errors.jsonl"
                    )
                self._pool_ended = True  # a new one starts for the next task, if there is one

    def _submit(
        self,
        in_flight: dict[Future[EpisodeOutcome], EpisodeTask],
        unsent: list[EpisodeTask],
        pending: Iterator[EpisodeTask],
    ) -> bool:
        """Fill the pool up to two tasks a worker (they keep it busy without queueing the whole sweep: a
        cancel is quick), starting a new pool after a broken one; True when it turns out broken (the task it
        refused is kept in ``unsent`` for the next pool: it never ran)."""
        from concurrent.futures.process import BrokenProcessPool

        while len(in_flight) < 2 * self.workers:
            task = unsent.pop() if unsent else next(pending, None)
            if task is None:
                return False
            if self._pool_ended:
                self._start_pool()
            try:
                in_flight[self._pool.submit(_run_in_pool, task)] = task
            except BrokenProcessPool:
                unsent.append(task)
                return True
        return False

    def finished(self, wait_s: float) -> tuple[list[EpisodeOutcome], int]:
        """At a stop (pipelines.experiments.sweep_stop): the outcomes of the episodes handed to the pool and
        not yielded that come back within ``wait_s`` (those ready at once first), and how many of the others
        the workers were running then (cut: ``close`` ends them). The queued ones are not waited for: those no
        worker took are cancelled, and a worker that frees up starts none it takes (pool_stop): nothing of
        them ran, and a resume runs them."""
        from concurrent.futures import wait

        in_flight = self._in_flight
        self._stop.stop()
        taken = [future for future in in_flight if not future.cancel()]
        wait(taken, timeout=wait_s)
        # a future failed by the pool (a worker died meanwhile) finished no episode; nor did one NotStarted
        back = [f.result() for f in taken if f.done() and f.exception() is None]
        in_flight.clear()
        return back, min(self._stop.running(), len(taken) - len(back))

    def _lost(self, in_flight: dict[Future[EpisodeOutcome], EpisodeTask]) -> tuple[list[EpisodeOutcome], int]:
        """The outcomes of the episodes in flight when the pool broke, and how many of them finished before
        it: an error for each of the others (any of them may be the one that killed its worker)."""
        from concurrent.futures import wait
        from concurrent.futures.process import BrokenProcessPool

        # A broken pool fails every future it holds at once; the bound is for one that a submit racing the
        # break slipped past (the pool's own clean-up does not take its lock), which would never complete.
        wait(in_flight, timeout=BROKEN_POOL_WAIT_S)
        self._end_pool()  # every process ended and joined: their exit codes are known
        deaths = self._deaths()
        outcomes: list[EpisodeOutcome] = []
        finished = 0
        for future, task in in_flight.items():
            if (
                future.done()
                and not future.cancelled()
                and not isinstance(future.exception(), BrokenProcessPool)
            ):
                outcomes.append(future.result())
                finished += 1
                continue
            error = (
                f"worker process died ({deaths}) while this episode was in flight, with {len(in_flight) - 1} "
                "other(s) on the same pool; any of them may have ended it (a segfault, the OOM killer, a "
                "controller exiting); a rerun tries it again"
            )
            outcomes.append(EpisodeOutcome(task.key, error=error))
        in_flight.clear()
        return outcomes, finished

    def _deaths(self) -> str:
        """How the pool's processes ended, e.g. "killed by SIGKILL", "exit status 3"."""
        import signal

        ends = set()
        for process in self._processes:
            code = process.exitcode
            if code is None or code == -signal.SIGTERM:  # alive, or ended by the broken pool's clean-up
                continue
            if code >= 0:
                ends.add(f"exit status {code}")
            else:
                known = -code in signal.valid_signals()
                ends.add(f"killed by {signal.Signals(-code).name if known else f'signal {-code}'}")
        return ", ".join(sorted(ends)) or "ended abruptly"

    def close(self) -> None:
        try:
            self._end_pool(grace_s=CLOSE_GRACE_S if self._drained else 0.0)
        finally:  # a Ctrl-C in the grace below still ends the workers and releases the folder
            if self._own_root is not None:
                release_scratch_root(self._own_root)

    def _end_pool(self, grace_s: float = 0.0) -> None:
        # Cancel what has not started, end the running episodes (never written: a rerun runs them) now; idle,
        # the workers get ``grace_s`` to exit of themselves, closing their controllers (_init_pool_worker).
        self._note_processes()
        self._stop.close()  # a SIGTERM now ends a worker at once, whatever it holds (pool_stop)
        self._pool.shutdown(wait=False, cancel_futures=True)
        try:
            deadline = time.monotonic() + grace_s
            for process in self._processes:
                process.join(timeout=max(0.0, deadline - time.monotonic()))
        finally:
            for process in self._processes:
                if process.is_alive():
                    process.terminate()
        for process in self._processes:
            process.join(timeout=5)
        for process in self._processes:  # one that takes no signal (C code that does not return): for sure
            if process.is_alive():
                process.kill()
                process.join(timeout=5)
