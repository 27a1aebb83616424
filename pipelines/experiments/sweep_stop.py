"""What a sweep that stops part way keeps of the episodes its other workers ran.

A sweep stops (SweepStopped) at a worker's refusal of weights replaced in the zoo (checked_weights), at its
Ray cluster's silence (backends.GCS_GONE_S), at workers that keep dying, or at its first episodes all
raising. The driver stopped at once and closed the backend: the episodes the other workers had finished, or
were about to hand back, ended unrecorded, and a rerun ran them again (met with ``--workers 2`` and a `zoo
add --replace` during a Table II sweep: three episodes in flight came back within 5 s of the refusal, all
lost). Now the driver writes what the backend's ``finished`` gives back within ``STOP_WAIT_S`` (a backend of
one's own without it: nothing), as it writes every outcome; the episodes still running then are cut, and
the stop's line says how many, which a resume runs. The stop also carries the workers the backend ran at
once (``SweepStopped.workers``): the report's CPU projection divides by them, as a finished run's does.

An interrupt (Ctrl-C, or SIGTERM and SIGHUP taken as one: pipelines.loop.interrupt) is such a stop too. The
driver closed the backend at once, and the episodes its workers were running were lost, however near their
end (`sweep --workers 2` on Table II with constant velocity, episodes of about a second: Ctrl-C cut the two
running). Now it says so and waits for them, as at any other stop; a second interrupt ends the wait at
once (raised inside ``finished``), and the line that asks for a rerun counts the episodes cut. A
SIGTERM or SIGHUP sent to the sweep's whole process group (`timeout`, a closed terminal) reaches the process
pool's workers as well: each holds the first (idle too), finishes the episode it runs and starts no other, as
at a signal to the driver alone, and the driver then ends them (pipelines.experiments.pool_stop).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final

from pipelines.errors import PipelineError
from pipelines.experiments.worker import EpisodeOutcome
from predictors.text_table import counted

# How long a stop waits for the episodes in flight (a worker's result on its way, an episode about to end):
# bounded, so that a stop on a dead cluster or a hung episode never hangs; those still running are cut.
STOP_WAIT_S: Final[float] = 5.0


@dataclass(frozen=True)
class Kept:
    """What a stop made of the episodes in flight: ``cut``, those running on the workers when the wait ended
    (unrecorded); ``unkept``, the stop line's tail for those back whose writing failed ("" for none)."""

    cut: int = 0
    unkept: str = ""

    def __post_init__(self) -> None:
        if self.cut < 0:
            raise ValueError(f"Kept.cut counts episodes: expected 0 or more, got {self.cut}")

    def note(self) -> str:
        """The stop line's tail: the episodes cut, then a failed write of those back."""
        return cut_note(self.cut) + self.unkept


def keep_finished(
    backend: Any, keep: Callable[[EpisodeOutcome], None], say: Callable[[str], None] | None = None
) -> Kept:
    """Write (``keep``) each outcome ``backend`` gives back within STOP_WAIT_S of a stop; the episodes cut.
    Another worker's refusal (``stop``) ran nothing and is not written. ``say``: told first that the wait
    begins, where the backend waits (an interrupt's: otherwise the user's Ctrl-C met seconds of silence, and a
    second one, which stops at once, lost what the wait would keep). A ``keep`` that raises (a full disk, a
    backend of one's own answering for an episode it was not given) ends the writing: its error joins the
    stop's line, which it replaced, so that the user read the failure and not why the sweep stopped."""
    finished = getattr(backend, "finished", None)
    if finished is None:  # a backend of one's own, or inline: its episode ran in the driver, cut there
        return Kept()
    if say is not None:
        say(
            f"interrupted: recording the episodes the workers finish within {STOP_WAIT_S:g} s; interrupt "
            "again to stop at once"
        )
    back, cut = finished(STOP_WAIT_S)
    ran = [outcome for outcome in back if outcome.stop is None]
    for written, outcome in enumerate(ran):
        try:
            keep(outcome)
        except Exception as exc:  # a second interrupt (no Exception) still ends the stop at once
            return Kept(int(cut), _unkept_note(len(ran) - written, exc))
    return Kept(int(cut))


def _unkept_note(unkept: int, exc: Exception) -> str:
    why = str(exc) if isinstance(exc, PipelineError) else f"{type(exc).__name__}: {exc}"
    return (
        f"; {counted(unkept, 'episode')} the workers finished {'was' if unkept == 1 else 'were'} not "
        f"recorded (a resume runs {'it' if unkept == 1 else 'them'}): {why}"
    )


def cut_note(cut: int) -> str:
    """The stop line's tail for ``cut`` episodes in flight, unrecorded ("" for none)."""
    if cut == 0:
        return ""
    return (
        f"; {counted(cut, 'episode')} in flight on the workers {'was' if cut == 1 else 'were'} cut "
        f"unrecorded (a resume runs {'it' if cut == 1 else 'them'})"
    )
