"""Ctrl-C in the closed loop, taken between control steps.

CasADi's Python bindings check for Ctrl-C inside a solve and, finding one, write a line of their own on
stderr ("KeyboardInterrupt" from the solver call, or IPOPT's 'WARNING("KeyboardInterruptException")')
before the interrupt reaches Python, so that an interrupted ``crowdmpc simulate`` printed it above the
CLI's one line. While an episode runs, a SIGINT is therefore noted rather than raised, and raised where the
step in progress ends: at most one control step later, whose solves are bounded by their wall budget. A
second Ctrl-C before then is raised at once, for a user who will not wait, and so is the first once the step
has held it ``STEP_GRACE_S``: a plugin's step that hangs kept one SIGTERM (``timeout``, a scheduler's stop,
which sends no second) from ever stopping the run.

Only in the main thread (the only one that may set a handler) and only while SIGINT has Python's default
handler: a program, a sweep worker or a test that set its own keeps it, and gets the interrupt as before.

SIGTERM (``kill``, ``timeout``, a job scheduler's stop) and SIGHUP (a closed terminal) are taken as a Ctrl-C
(``terminate_as_interrupt``): the default action ended the process at once, with no finally run, so an
interrupted ``crowdmpc simulate`` lost the episodes it had finished and left its MCAP log as a ``.part``.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType
from typing import Any, Final

# Seconds a step may hold a noted interrupt before it is raised inside the step: a control step's solves are
# bounded by their wall budget (below 1 s; the NLPs are built at reset, not in a step)
STEP_GRACE_S: Final[float] = 5.0


class StepInterrupt:
    """The Ctrl-C noted during a step: ``check()`` raises it; or another exception deferred to the step's
    end (``defer_to_step_end``: a sweep's episode time limit), or one overdue (``overdue_at_step_ends``)."""

    def __init__(self) -> None:
        self.pending = False
        self.deferred: BaseException | None = None
        self._timer: threading.Timer | None = None

    def note(self, signum: int, frame: FrameType | None) -> None:
        if self.pending:
            self.disarm()
            raise KeyboardInterrupt
        self.pending = True
        self._arm(signum)

    def _arm(self, signum: int) -> None:
        """The same signal again, to the main thread, after ``STEP_GRACE_S``: the second, raised at once."""
        main = threading.main_thread().ident
        if main is None or not hasattr(signal, "pthread_kill"):
            return
        self._timer = threading.Timer(STEP_GRACE_S, signal.pthread_kill, (main, signum))
        self._timer.daemon = True
        self._timer.start()

    def disarm(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def check(self) -> None:
        if self.pending:
            self.pending = False
            self.disarm()
            raise KeyboardInterrupt
        if self.deferred is not None:
            deferred, self.deferred = self.deferred, None
            raise deferred
        if _overdue is not None and threading.current_thread() is threading.main_thread():
            raise _overdue


def defer_to_step_end(exc: BaseException) -> bool:
    """Have ``exc`` raised where the control step in progress ends, as a Ctrl-C is, if an episode's steps
    are running in this (the main) thread; False otherwise (then raise it yourself). Raised inside a solve,
    CasADi printed its own interrupt lines and IPOPT took it for a user's stop, the raise lost."""
    if _stepping is None or threading.current_thread() is not threading.main_thread():
        return False
    _stepping.deferred = exc
    return True


def overdue_at_step_ends(exc: BaseException | None) -> None:
    """Have ``exc``, raised at once outside a step, raised again where each control step in this (the main)
    thread ends, until None clears it: C code may clear a raise (CasADi's SWIG conversions, as a predictor's
    exported encoder ran in an MPC's reset), and a sweep's limit met there let the episode run every step."""
    global _overdue
    _overdue = exc


_stepping: StepInterrupt | None = None  # the episode's, in the main thread, while its steps run
_overdue: BaseException | None = None  # overdue_at_step_ends'


@contextlib.contextmanager
def interrupts_between_steps() -> Iterator[StepInterrupt]:
    """Around an episode's steps, and a sweep driver's write of an outcome (experiments.outcome_write): a
    Ctrl-C is raised by the ``check()`` that follows it (one a step), or on leaving the block, so none is
    lost; with another SIGINT handler in place (or SIGINT ignored) that handler keeps Ctrl-C, and ``check()``
    raises only a SIGTERM or SIGHUP noted by ``terminate_as_interrupt``; off the main thread as before
    (``check()`` then never raises)."""
    step = StepInterrupt()
    if threading.current_thread() is not threading.main_thread():
        yield step
        return
    global _stepping
    outer, _stepping = _stepping, step  # terminate_as_interrupt's note, whatever SIGINT's handler
    takes_ctrl_c = signal.getsignal(signal.SIGINT) is signal.default_int_handler
    if takes_ctrl_c:
        signal.signal(signal.SIGINT, step.note)
    try:
        yield step
    finally:
        _stepping = outer
        if takes_ctrl_c:
            signal.signal(signal.SIGINT, signal.default_int_handler)
        step.disarm()  # the block is left: nothing is held any more (what is pending, check raises)
    step.check()  # noted after the last step's check, the block ending normally


_signalled: int | None = None  # the SIGTERM or SIGHUP terminate_as_interrupt took, in this process


def stop_status() -> int:
    """The exit status of a command that stopped at an interrupt: 128 + the signal's number, as a shell
    reports a process the signal ended, 130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP: a batch script
    tells a scheduler's stop from a user's Ctrl-C (every one gave 130)."""
    return 128 + int(_signalled or signal.SIGINT)


def forget_handled_interrupts() -> None:
    """CPython notes a KeyboardInterrupt that ends code run from a string (``exec`` of source, as dataclasses
    and namedtuples generate their methods while torch or CasADi is imported) and, once the interpreter has
    finished, ends the process by SIGINT whatever status it exits with: a `kill` there, taken as Ctrl-C and
    reported as 143, ended the process as Ctrl-C does (130 in a shell, -2 to a Python parent). Running any
    code from a string clears that note (pythonrun.c, run_eval_code_obj); for a program that has handled
    every interrupt, as the CLI's ``main`` has once it returns."""
    exec("", {})


@contextlib.contextmanager
def terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM and SIGHUP end the block like Ctrl-C: a sweep stops its workers, removes its scratch and
    resumes on a rerun; calibrate takes its blocks back; simulate reports the episodes it finished. During an
    episode's step the signal is noted as a Ctrl-C is (``interrupts_between_steps``), so that CasADi prints
    nothing of its own. A signal the caller ignores (SIGHUP under ``nohup``) stays ignored. Only the main
    thread may set signal handlers; elsewhere the default actions stay."""
    global _signalled
    _signalled = None  # each command's own (a thread's too, which sets no handler): one before is no cause
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: Any) -> None:
        global _signalled
        _signalled = signum
        # the episode's step in progress, even where SIGINT is not the loop's (ignored by a background job's
        # shell): raised in CasADi's solve, it printed CasADi's own "KeyboardInterrupt" above the CLI's line
        if _stepping is not None:  # its own signal: SIGINT, which the grace would send, may be ignored here
            _stepping.note(signum, frame)
            return
        raise KeyboardInterrupt(signal.Signals(signum).name)

    signals = [signal.SIGTERM] + ([signal.SIGHUP] if hasattr(signal, "SIGHUP") else [])
    # one the caller ignores stays ignored: `nohup crowdmpc sweep ...` is meant to outlive its terminal
    signals = [s for s in signals if signal.getsignal(s) is not signal.SIG_IGN]
    saved = {s: signal.signal(s, interrupt) for s in signals}
    try:
        yield
    finally:
        for s, handler in saved.items():
            signal.signal(s, handler)
