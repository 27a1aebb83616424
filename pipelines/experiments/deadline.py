"""A wall-clock limit on each episode of a sweep (``[sweep] episode_timeout_s``, ``--episode-timeout S``).

Why. A sweep runs thousands of episodes unattended, some with its users' own controllers (plugins). One that
never returned (a plugin waiting on a lock or looping in ``act``) held its worker for good: the other workers
finished their share, and the sweep then waited forever with nothing in errors.jsonl to say why. With a
limit, the worker stops the episode when its time runs out, hands the driver an error naming the limit and
where the episode was (errors.jsonl; a rerun tries the episode again), and goes on with the next.

What it counts: the episode, from its reset to its record, not the build of its cell's controller (a first
episode's gcc compile or solver build, seconds, is no hang).

How. A real-time interval timer (``setitimer``) raises ``EpisodeTimeout`` in the worker's main thread, where
every backend runs its episodes (the pool's processes, Ray's actors, the inline driver). It derives from
BaseException, as KeyboardInterrupt does, so that a controller's ``except Exception`` does not swallow it.
Python acts on the timer between bytecodes: an episode inside one long C call (a CasADi solve, itself bounded
by ``mpc.time_limit_s``; a plugin's C extension) is stopped when that call returns. While the episode's steps
run it is raised where the step in progress ends, as a Ctrl-C is (``pipelines.loop.interrupt``): raised inside
a solve, CasADi printed its interrupt lines and IPOPT took it for a user's stop, the raise lost. A step that
outlasts the limit once more is a hang (a plugin looping in ``act``): the timer's next firing raises at once.
A raise outside the steps that C code cleared (a predictor's CasADi encoder in an MPC's reset) is raised again
where the next step ends: the episode ran every step past the limit, to be stopped where it ended.
"""

from __future__ import annotations

import contextlib
import math
import signal
import threading
from collections.abc import Iterator
from typing import Any, Final

from pipelines.errors import PipelineError
from pipelines.loop.interrupt import defer_to_step_end, overdue_at_step_ends

# The longest limit a timer is armed for: setitimer refuses one past about 9.2e9 s (2**63 ns), raising
# OverflowError in every episode of a sweep that asked for one (--episode-timeout 1e10). A limit beyond it is
# none in practice (31 years), and refusing it would refuse the sweep folders that recorded one.
MOST_TIMER_S: Final[float] = 1e9


class EpisodeTimeout(BaseException):
    """An episode ran past its wall-clock limit (s, the argument)."""


def check_timeout(seconds: Any, name: str = "episode_timeout_s") -> float | None:
    """``seconds`` as a limit: None (none) or a finite number > 0; else a PipelineError naming ``name``."""
    if seconds is None:
        return None
    number = isinstance(seconds, int | float) and not isinstance(seconds, bool)
    if not (number and math.isfinite(seconds) and seconds > 0):
        raise PipelineError(f"{name} must be a number of seconds > 0, or unset for no limit; got {seconds!r}")
    return float(seconds)


@contextlib.contextmanager
def deadline(seconds: float | None) -> Iterator[None]:
    """Raise ``EpisodeTimeout`` in the block once ``seconds`` of wall-clock time have passed (None, or past
    ``MOST_TIMER_S``: never).
    The timer is cleared on the way out; one that fires in that instant raises from here, as does one whose
    raise C code swallowed."""
    if seconds is None or seconds > MOST_TIMER_S:
        yield
        return
    if threading.current_thread() is not threading.main_thread():  # signals reach the main thread alone
        raise PipelineError("an episode time limit needs the episodes run on their process's main thread")

    fired = False

    def expire(signum: int, frame: Any) -> None:
        nonlocal fired
        if not fired and defer_to_step_end(EpisodeTimeout(seconds)):
            # raised where the step ends, not inside a CasADi solve; a step that outlasts the limit once
            # more is a hang, and the next firing raises at once
            fired = True
            signal.setitimer(signal.ITIMER_REAL, seconds)
            return
        fired = True
        overdue_at_step_ends(EpisodeTimeout(seconds))  # in case C code clears this raise
        raise EpisodeTimeout(seconds)

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        overdue_at_step_ends(None)
    if fired:
        # The raise was lost: C code the handler ran inside cleared it (CasADi's SWIG layer tries conversions
        # and clears their errors: one that fired while an NLP was built let its episode finish past a 1 ms
        # limit, in 1 to 2 of 4 episodes). The episode ran past its limit all the same.
        raise EpisodeTimeout(seconds)


def timeout_error(seconds: float, trace: str) -> str:
    """The error a timed-out episode leaves in errors.jsonl: the limit, then where the episode was."""
    return (
        f"the episode ran past the sweep's episode_timeout_s = {seconds:g} s of wall-clock time and was "
        "stopped; its controller was dropped (the cell's next episode builds it again) and a rerun tries the "
        f"episode again. Where it was:\n{trace}"
    )
