"""Ctrl-C in the closed loop, taken between control steps.

CasADi's Python bindings check for Ctrl-C inside a solve and, finding one, write a line of their own on
stderr ("KeyboardInterrupt" from the solver call, or IPOPT's 'WARNING("KeyboardInterruptException")')
before the interrupt reaches Python, so that an interrupted ``crowdmpc simulate`` printed it above the
CLI's one line. While an episode runs, a SIGINT is therefore noted rather than raised, and raised where the
step in progress ends: at most one control step later, whose solves are bounded by their wall budget. A
second Ctrl-C before then is raised at once, for a user who will not wait.

Only in the main thread (the only one that may set a handler) and only while SIGINT has Python's default
handler: a program, a sweep worker or a test that set its own keeps it, and gets the interrupt as before.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType


class StepInterrupt:
    """The Ctrl-C noted during a step: ``check()`` raises it."""

    def __init__(self) -> None:
        self.pending = False

    def note(self, signum: int, frame: FrameType | None) -> None:
        if self.pending:
            raise KeyboardInterrupt
        self.pending = True

    def check(self) -> None:
        if self.pending:
            self.pending = False
            raise KeyboardInterrupt


@contextlib.contextmanager
def interrupts_between_steps() -> Iterator[StepInterrupt]:
    """Around an episode's steps: a Ctrl-C is raised by the ``check()`` that follows it (one a step), or on
    leaving the block, so none is lost; with another SIGINT handler in place, or off the main thread, as
    before (``check()`` then never raises)."""
    step = StepInterrupt()
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield step
        return
    signal.signal(signal.SIGINT, step.note)
    try:
        yield step
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    step.check()  # noted after the last step's check, the block ending normally
