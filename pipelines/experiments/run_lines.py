"""sweep.json's run lines: a line per run of the sweep (``pipelines.experiments.sweep._add_run``: its code,
settings and cells), which each record names by number (its ``run``), and the two kinds of line that are no
run of the sweep's own: a run the records name that sweep.json no longer listed (``lost_runs``: code unknown),
and a run of another sweep whose episodes ``sweep --reuse`` took (pipelines.experiments.reuse: the code of
those episodes, not a run here). Written whole, in one rename (``write_sweep_file``)."""

from __future__ import annotations

import json
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any, Final

from pipelines.errors import PipelineError, print_note, writes_named
from pipelines.experiments.log import EPISODES_FILE, SWEEP_FILE, write_whole
from pipelines.experiments.record_checks import DAMAGED
from pipelines.plain_json import plain

MAX_LOST_RUNS: Final[int] = 1000  # runs a log's records may name past sweep.json's (lost_runs)
REUSED: Final[str] = "reused_from"  # a reused line's mark: the folder whose run it is (``run_there``: which)


def is_reused(run: Any) -> bool:
    """A line ``sweep --reuse`` copied from another sweep: the code of episodes it took, not a run here."""
    return isinstance(run, dict) and REUSED in run


def own_runs(runs: Sequence[Any]) -> list[int]:
    """The numbers (from 1) of sweep.json's run lines that are runs of this sweep, not ``is_reused``."""
    return [k for k, run in enumerate(runs, start=1) if not is_reused(run)]


def run_number(record: Mapping[str, Any]) -> int | None:
    """The line of sweep.json a record names (its ``run``, from 1); None where it names none, or no number
    (a record from before records kept it, or a damaged one: any run may have made it)."""
    run = record.get("run")
    return run if isinstance(run, int) and not isinstance(run, bool) else None


def runs_named(runs: Sequence[Any], used: Collection[int | None]) -> list[Any]:
    """The lines of ``runs`` that the records' ``used`` numbers (``run_number``) name, in number order; every
    line where a record names none; a number past the lines, or below 1 (a damaged record: run 0 was passed
    over where -1 was counted), a run the file lost (``{"lost": ""}``)."""
    if None in used:
        return list(runs)
    named = sorted(k for k in used if k is not None)
    return [runs[k - 1] if 1 <= k <= len(runs) else {"lost": ""} for k in named]


def is_lost(run: Any) -> bool:
    """A run line ``lost_runs`` added: the run's own line was gone, its code and config unknown."""
    return isinstance(run, dict) and "lost" in run


def split_lost(runs: list[Any]) -> tuple[list[Any], str]:
    """sweep.json's run lines of known code, and what the others are ("" for none): lines ``lost_runs`` added
    (the run's line was gone), and lines --reuse took of another sweep that lacked them."""
    kept = [run for run in runs if not is_lost(run)]
    reused = sum(map(is_reused, (run for run in runs if is_lost(run))))
    lost = len(runs) - len(kept) - reused
    parts = [
        f"{lost} run(s) {SWEEP_FILE} lost" if lost else "",
        f"{reused} reused run(s) their sweep's {SWEEP_FILE} lacked" if reused else "",
    ]
    text = ", ".join(filter(None, parts))
    return kept, f"{text}, code unknown" if text else ""


def lost_runs(out: Path, listed: int, last: int, began: int | None = None) -> list[dict[str, str]]:
    """A line for each run the records name (``last``: the highest ``run`` of any) past the ``listed`` lines
    of sweep.json, said on stderr: with sweep.json moved away, the next run took number 1, and the old
    records' ``"run": 1`` credited its code with their episodes. A number past ``MAX_LOST_RUNS`` of them is
    the log's damage, not runs (a line each would fill sweep.json). ``began``: the number of the run that
    found them (None: the next, ``last + 1``; --reuse's lines taken come between)."""
    lost = last - listed
    if lost <= 0:
        return []
    if lost > MAX_LOST_RUNS:
        raise PipelineError(
            f"{out / EPISODES_FILE}: a record names run {last}, {lost} past the {listed} {SWEEP_FILE} lists; "
            f"{DAMAGED}"
        )
    print_note(
        f"note: {out / EPISODES_FILE} holds episodes of {lost} run(s) {SWEEP_FILE} does not list; they are "
        "kept as runs of unknown code (a new --out starts afresh)"
    )
    began = last + 1 if began is None else began
    return [{"lost": f"not listed in {SWEEP_FILE} when run {began} began"} for _ in range(lost)]


def write_sweep_file(path: Path, meta: dict[str, Any]) -> None:
    """sweep.json's document into ``path`` in one rename, synced: a stop or a full disk halfway leaves the
    file as it was (a full disk's error names it)."""
    with writes_named(path):
        write_whole(path, (json.dumps(plain(meta), indent=1) + "\n").encode())
