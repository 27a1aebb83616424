"""A process pool's worker and a SIGTERM or SIGHUP sent to the sweep's process group while it updates the
episodes' count in memory the pool shares (pipelines.experiments.pool_stop)."""

from __future__ import annotations

import contextlib
import multiprocessing
import signal
from collections.abc import Iterator
from typing import Any

from pipelines.experiments import pool_stop


class _SignalledWhileLocked:
    """The pool's shared integers, whose lock, the first time it is taken, brings the worker a SIGTERM (as a
    process group's may come at any instruction)."""

    def __init__(self, shared: Any) -> None:
        self.shared = shared
        self.signalled = False

    def get_obj(self) -> Any:
        return self.shared.get_obj()

    @contextlib.contextmanager
    def get_lock(self) -> Iterator[None]:
        with self.shared.get_lock():
            if not self.signalled:
                self.signalled = True
                signal.raise_signal(signal.SIGTERM)  # its handler runs here, in the locked block
            yield


def _starts_an_episode_signalled_as_it_counts(shared: Any) -> None:
    pool_stop.take_part(_SignalledWhileLocked(shared))
    pool_stop.hold_stop_signals()
    pool_stop.run_unless_stopped(lambda: None)


def test_a_signal_as_a_worker_counts_its_episode_leaves_the_count_free():
    """The handler's default action, taken while the worker held the shared lock, ended it holding the lock
    for ever: the driver's stop (PoolStop.stop) and every other worker then waited on it without end. The
    signal is now taken as the lock is released: the episode, begun, holds it and runs."""
    context = multiprocessing.get_context("spawn")
    stop = pool_stop.PoolStop(context)
    worker = context.Process(target=_starts_an_episode_signalled_as_it_counts, args=(stop.shared,))
    worker.start()
    worker.join(timeout=60)
    try:
        lock = stop.shared.get_lock()
        assert lock.acquire(timeout=5), "the worker ended holding the pool's shared lock"
        lock.release()
        assert worker.exitcode == 0  # its episode ran, holding the signal
        assert stop.running() == 0
    finally:
        if worker.is_alive():
            worker.kill()
