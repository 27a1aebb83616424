"""What a process pool's driver and its workers share about a sweep's stop (ProcessBackend.finished): the
driver's word that the pool stops, after which a worker starts no episode it takes, and how many episodes the
workers are running, those a stop cuts.

The pool hands its workers more tasks than they run (its call queue holds one more than its workers; the
backend keeps two a worker in flight), and a task in the call queue counts as running to its future: no cancel
reaches it. The stop's line counted every task handed to the pool and not back as an episode cut, those that
never started too (`sweep --workers 1` interrupted in its first episode: "2 episodes in flight on the workers
were cut"), and a worker that finished within the stop's wait started the next one, to be cut. Now each worker
counts the episodes it runs in memory the pool shares, and refuses (``NotStarted``) those it takes once the
driver has said the pool stops."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

_T = TypeVar("_T")
_STOPPING, _RUNNING = 0, 1  # the shared integers: the driver's word, the episodes running


class NotStarted(Exception):
    """A task a worker took after the driver said the pool stops: never run (a resume runs it)."""


class PoolStop:
    """The driver's side, one per pool: ``shared`` goes to each worker (``take_part``) as it starts."""

    def __init__(self, context: Any) -> None:
        self.shared = context.Array("i", 2)  # spawned workers get it with their start (initargs)

    def stop(self) -> None:
        """Have the workers start no episode they take from now on."""
        with self.shared.get_lock():
            self.shared.get_obj()[_STOPPING] = 1

    def running(self) -> int:
        """The episodes the workers are running now (those of a worker that died in one included)."""
        with self.shared.get_lock():
            return int(self.shared.get_obj()[_RUNNING])


_shared: Any = None  # the worker's: its pool's PoolStop.shared


def take_part(shared: Any) -> None:
    """In a pool's worker, as it starts: the pool's shared integers."""
    global _shared
    _shared = shared


def run_unless_stopped(run: Callable[[], _T]) -> _T:
    """``run()``, counted as running while it runs; NotStarted once the driver has said the pool stops."""
    assert _shared is not None, "pool worker used before its initializer ran"
    with _shared.get_lock():
        counts = _shared.get_obj()
        if counts[_STOPPING]:
            raise NotStarted("the sweep stopped before this episode started")
        counts[_RUNNING] += 1
    try:
        return run()
    finally:
        with _shared.get_lock():
            _shared.get_obj()[_RUNNING] -= 1
