"""What a review keeps of a recording once read: a folder's review reads its files one at a time and lets go.

A ``Recording`` holds every decoded message: about 5 MB in memory for a 121 KB file of a 3-robot, 7-human
episode (100 such recordings read into one process took 503 MB). A sweep recording every episode (`crowdmpc
sweep --record all`; Table II has 10 000) read whole would not fit in memory, yet a folder's tables need
little of each run: its summary, its set-up, its control steps' times (pooled over a set-up), its warnings
and, with ``--check``, the check's result.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pipelines.logs.identity import run_identity
from pipelines.logs.reader import Recording
from pipelines.logs.review import summarize
from pipelines.logs.schema_check import check_recording


@dataclass(frozen=True, eq=False)  # an array field: == would be ambiguous; a digest is itself
class RunDigest:
    """One recording as a review uses it after reading."""

    summary: dict[str, Any]  # pipelines.logs.review.summarize
    identity: dict[str, Any] | None  # run_identity; None: no readable episode metadata (set-up unknown)
    solve_times_s: np.ndarray  # every control step's /mpc/solver solve_time_s
    warning: str | None  # Recording.warning (truncated)
    problems_warning: str | None  # Recording.problems_warning
    # --check: (messages checked, their errors: schema violations, messages left out); None when not asked.
    # The file's own problems are apart (``file_problems``, ``stopped_at``): a corrupt summary record is
    # no "invalid message", and a cut file whose messages all pass still fails the check.
    check: tuple[int, list[str]] | None
    file_problems: list[str]  # Recording.problems: bad chunks, corrupt records, bad metadata
    stopped_at: str | None  # truncated: what ended reading (Recording.stopped_at; None: no closing magic)
    record_policy: str | None  # a sweep's --record ("all", "failures"), from the "run" metadata; else None

    @property
    def file(self) -> str:
        return str(self.summary["file"])


def digest(rec: Recording, check: bool = False) -> RunDigest:
    """``rec``'s digest; ``check``: validate every message against its schema now, while it is in memory."""
    summary = summarize(rec)
    known = summary["controller"] is not None  # as a folder's set-ups have always been told apart
    return RunDigest(
        summary=summary,
        identity=run_identity(rec.episode(), rec.config()) if known else None,
        solve_times_s=np.array([m["solve_time_s"] for m in rec.data("/mpc/solver")], dtype=float),
        warning=rec.warning,
        problems_warning=rec.problems_warning,
        check=_message_check(rec) if check else None,
        file_problems=list(rec.problems),
        stopped_at=rec.stopped_at,
        record_policy=_record_policy(rec),
    )


def _message_check(rec: Recording) -> tuple[int, list[str]]:
    """``check_recording`` of the messages alone: its errors begin with ``rec.problems``, the file's own."""
    checked, errors = check_recording(rec)
    assert errors[: len(rec.problems)] == rec.problems
    return checked, errors[len(rec.problems) :]


def _record_policy(rec: Recording) -> str | None:
    """Which episodes the sweep that recorded ``rec`` kept (``crowdmpc sweep --record``); None for a
    recording of anything else, or one made before sweeps wrote it."""
    policy = rec.run_meta().get("record")
    return policy if isinstance(policy, str) else None
