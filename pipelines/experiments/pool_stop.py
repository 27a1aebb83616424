"""What a process pool's driver and its workers share about a sweep's stop (ProcessBackend.finished): the
driver's word that the pool stops, after which a worker starts no episode it takes, and how many episodes the
workers are running, those a stop cuts.

The pool hands its workers more tasks than they run (its call queue holds one more than its workers; the
backend keeps two a worker in flight), and a task in the call queue counts as running to its future: no cancel
reaches it. The stop's line counted every task handed to the pool and not back as an episode cut, those that
never started too (`sweep --workers 1` interrupted in its first episode: "2 episodes in flight on the workers
were cut"), and a worker that finished within the stop's wait started the next one, to be cut. Now each worker
counts the episodes it runs in memory the pool shares, and refuses (``NotStarted``) those it takes once the
driver has said the pool stops.

A SIGTERM or SIGHUP sent to the sweep's whole process group (`timeout 30 crowdmpc sweep ...`, a closed
terminal) reached the workers too, whose default action ended them at once: the episodes they ran were cut,
where a signal to the driver alone let them finish within the stop's wait (sweep_stop) and recorded them.
Ignoring the signals would not do: the pool's own clean-up of a broken pool ends its workers by SIGTERM and
joins them without a bound. So a worker holds the first one (``hold_stop_signals``), idle too (ended, it
broke the pool, and the break failed the futures of the episodes the others ran): the episode it runs goes
on, and it starts no other; it ends at once once the driver has said it closes the pool (``PoolStop.close``,
then SIGTERM and, past a bound, SIGKILL), at a second signal, or ``HOLD_S`` after the signal, which the
driver's wait ends before. A jit compile in the episode goes on too: mpc.compiler.ended_after_cleanup asks
the handler (its ``holds``) before it stops the compile."""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any, Final, TypeVar

from pipelines.experiments.sweep_stop import STOP_WAIT_S

_T = TypeVar("_T")
# the shared integers: the driver's word that the pool stops, the episodes running, its word that it closes
_STOPPING, _RUNNING, _CLOSING = 0, 1, 2
# How long a worker holds a SIGTERM or SIGHUP while its episode runs: past the driver's wait for the episodes
# (STOP_WAIT_S, from the same signal), so that the driver ends the pool first; the bound where it does not.
HOLD_S: Final[float] = STOP_WAIT_S + 5.0


class NotStarted(Exception):
    """A task a worker took after the driver said the pool stops: never run (a resume runs it)."""


class PoolStop:
    """The driver's side, one per pool: ``shared`` goes to each worker (``take_part``) as it starts."""

    def __init__(self, context: Any) -> None:
        self.shared = context.Array("i", 3)  # spawned workers get it with their start (initargs)

    def stop(self) -> None:
        """Have the workers start no episode they take from now on."""
        with self.shared.get_lock():
            self.shared.get_obj()[_STOPPING] = 1

    def close(self) -> None:
        """Have a SIGTERM or SIGHUP end each worker at once from now on, whatever it runs."""
        with self.shared.get_lock():
            self.shared.get_obj()[_CLOSING] = 1

    def running(self) -> int:
        """The episodes the workers are running now (those of a worker that died in one included)."""
        with self.shared.get_lock():
            return int(self.shared.get_obj()[_RUNNING])


_shared: Any = None  # the worker's: its pool's PoolStop.shared
_held: int | None = None  # the worker's: the signal it holds
_counting = False  # the worker's: its main thread holds the shared lock (``_counts``)
_deferred: list[int] = []  # the worker's: a SIGTERM or SIGHUP that came meanwhile


def take_part(shared: Any) -> None:
    """In a pool's worker, as it starts: the pool's shared integers."""
    global _shared
    _shared = shared


def run_unless_stopped(run: Callable[[], _T]) -> _T:
    """``run()``, counted as running while it runs; NotStarted once the driver has said the pool stops."""
    with _counts() as counts:
        if counts[_STOPPING]:
            raise NotStarted("the sweep stopped before this episode started")
        held = _held is not None  # read in the block: a signal taken as it ends holds for the episode begun
        if not held:
            counts[_RUNNING] += 1
    if held:  # signalled, not by the sweep's stop: the worker ends when HOLD_S is up or the driver ends it
        while True:  # not NotStarted: a worker signalled alone would take every task the pool hands it
            time.sleep(HOLD_S)
    try:
        return run()
    finally:
        with _counts() as counts:
            counts[_RUNNING] -= 1


@contextlib.contextmanager
def _counts() -> Iterator[Any]:
    """The shared integers, locked; a SIGTERM or SIGHUP that comes meanwhile is taken once the lock is free:
    its default action, taken inside, ended the worker holding the lock, and the other workers and the
    driver's stop (``PoolStop.stop``) then waited on it for ever. (Blocking the signals would not do: one
    sent to the process reaches another of its threads, and Python runs the handler in this one.)"""
    global _counting
    assert _shared is not None, "pool worker used before its initializer ran"
    _counting = True
    try:
        with _shared.get_lock():
            yield _shared.get_obj()
    finally:
        _counting = False
        while _deferred:  # in order: a second one ends the worker, as it would have outside
            _on_stop_signal(_deferred.pop(0), None)


_STOP_SIGNALS: Final[tuple[signal.Signals, ...]] = tuple(
    getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name)
)


def hold_stop_signals() -> None:
    """In a pool's worker, as it starts: SIGTERM and SIGHUP, where their default action is in force (SIGHUP
    under nohup stays ignored), are held (the module's docstring says how)."""
    for signum in _STOP_SIGNALS:
        if signal.getsignal(signum) is signal.SIG_DFL:
            signal.signal(signum, _on_stop_signal)


def _holds(signum: int) -> bool:
    """Whether the worker holds ``signum`` now (the first, the pool not closing; idle too: one that ended
    broke the pool, whose break failed the futures of the episodes the other workers ran, held to finish);
    once it does, the same signal comes again HOLD_S later, to the main thread, and ends it."""
    global _held
    if _held is not None or _shared is None or _shared.get_obj()[_CLOSING]:
        return False
    _held = signum
    main = threading.main_thread().ident
    if main is not None:
        timer = threading.Timer(HOLD_S, signal.pthread_kill, (main, signum))
        timer.daemon = True
        timer.start()
    return True


def _on_stop_signal(signum: int, frame: FrameType | None) -> None:
    if _counting:  # taken as the lock is released (_counts)
        _deferred.append(signum)
        return
    if not _holds(signum):  # the default action, now: the worker ends as it was told to
        signal.signal(signum, signal.SIG_DFL)
        signal.raise_signal(signum)


_on_stop_signal.holds = _holds  # type: ignore[attr-defined]  # read by mpc.compiler.ended_after_cleanup
