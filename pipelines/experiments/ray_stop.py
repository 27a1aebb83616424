"""What a Ray sweep's stop keeps of the episodes its actors hold (RayBackend.finished), and how many it cuts.

Each actor holds two episodes (RayBackend.run) and runs one at a time, in the order they were handed to it:
of those not back, the earliest is running and the other never started. The stop's line counted every
episode not back as cut, the queued ones too (`sweep --workers 1` interrupted in its first episode: "2
episodes in flight on the workers were cut"), and an actor whose episode came back within the stop's wait
started its queued one, which the stop then cut. Now the driver's word that the sweep stops is held by a
small actor of its own (``StopFlag``), which each episode actor asks before it starts an episode
(``started_unless_stopped``): one taken after the stop is handed back unstarted (None), and each actor counts
as cut at most the one episode it runs. ``ray.cancel`` does not do: a cancel that reaches an actor as its
episode ends still lets the queued one run, and that one's outcome comes back cancelled all the same.
"""

from __future__ import annotations

import contextlib
from typing import Any, Final

from pipelines.experiments.worker import EpisodeOutcome

# How long a call about the stop, or a get of an episode back already, may take: bounded, on a cluster going
# away (an actor whose flag does not answer starts its episode, as before the stop).
ASK_S: Final[float] = 5.0


class StopFlag:
    """In a Ray actor of no CPU, one per backend: the driver's word that the sweep stops."""

    def __init__(self) -> None:
        self._stopped = False

    def stop(self) -> None:
        self._stopped = True

    def stopped(self) -> bool:
        return self._stopped


def stopped(ray: Any, flag: Any) -> bool:
    """In an episode actor: whether the driver said the sweep stops (``flag``, a StopFlag actor's handle)."""
    try:
        return bool(ray.get(flag.stopped.remote(), timeout=ASK_S))
    except Exception:  # the flag's actor lost, or its node: run the episode as before any stop
        return False


def finished_on_actors(
    ray: Any, held: dict[Any, tuple[int, Any, Any]], wait_s: float, gcs_gone: bool
) -> tuple[list[EpisodeOutcome], int]:
    """The outcomes of the episodes ``held`` (object ref -> (slot, actor, task); the flag already set) that
    come back within ``wait_s``, and how many were running and did not: an actor runs one episode at a time,
    so whatever else of its own is unfinished never started. Once the cluster's GCS is gone (``gcs_gone``)
    only those back already are taken: Ray's waits would wait on it."""
    if not held:
        return [], 0
    refs = list(held)
    done, _ = ray.wait(refs, num_returns=len(refs), timeout=0.0 if gcs_gone else wait_s)
    lost = getattr(ray.exceptions, "RayError", ray.exceptions.RayActorError)
    back: list[EpisodeOutcome] = []
    unfinished: set[Any] = set(refs) - set(done)  # still out, or back with no episode (its actor died)
    for ref in done:
        try:  # back already: a bounded get all the same, on a cluster going away
            outcome = ray.get(ref, timeout=ASK_S)
        except lost:  # its actor died, or it did not come: no episode finished
            unfinished.add(ref)
            continue
        if outcome is not None:  # None: taken after the stop, never started (a resume runs it)
            back.append(outcome)
    actors: dict[int, set[Any]] = {}
    for ref, (_, actor, _) in held.items():
        actors.setdefault(id(actor), set()).add(ref)
    return back, sum(1 for own in actors.values() if own & unfinished)


def say_stop(ray: Any, flag: Any) -> None:
    """Set ``flag`` (a StopFlag actor's handle) and wait, bounded, until it is set: from then on no episode
    actor starts an episode it takes."""
    with contextlib.suppress(Exception):  # the flag's actor lost: the actors run what they hold, counted
        ray.get(flag.stop.remote(), timeout=ASK_S)
