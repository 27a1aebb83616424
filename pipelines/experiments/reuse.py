"""``crowdmpc sweep --reuse DIR``: a new sweep folder seeded with another sweep's episodes of the cells the
two plans share, so that they are not run again.

A cell's key holds everything that defines its episodes (controller, predictor, flocking, coupling, every
setting, margins, world, crowd size, robots: ``Cell.key``), and an episode's key adds its scenario and seed,
so a record of another sweep under a key this plan has is this plan's episode, run. Table III's F cells are
Table II's CMPC cells: the paper-scale Table III ran its 5000 F episodes again, or was seeded by hand with
Table II's lines, whose code the new folder's table.md then called "unknown". Here each record taken keeps
its episode as it is, under this experiment's method label, and its run's line of the source's sweep.json
(code, settings, cells) comes with it, marked ``reused_from``; then the sweep runs the rest as a resume does.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pipelines.errors import PipelineError
from pipelines.experiments.log import (
    EPISODES_FILE,
    PART_SUFFIX,
    SWEEP_FILE,
    check_sweep_directory,
    episode_log,
    read_sweep_file,
    sweep_lock,
)
from pipelines.experiments.tasks import EpisodeTask
from pipelines.plain_json import plain


def reusable(source: Path, out: Path, tasks: Sequence[EpisodeTask]) -> tuple[list[dict[str, Any]], list[Any]]:
    """The records of ``source`` (a sweep folder) that are episodes of ``tasks``, relabelled for them, and
    the source's run lines; PipelineError for a source that is no sweep, is ``out`` itself, or an ``out``
    that holds a sweep already (its records are its own: a resume needs no seed)."""
    option = f"--reuse {source}"
    if not (source / EPISODES_FILE).is_file() or not (source / SWEEP_FILE).is_file():
        raise PipelineError(f"{option}: not a sweep folder (it holds no {EPISODES_FILE} and {SWEEP_FILE})")
    if out.exists() and os.path.samefile(out, source):
        raise PipelineError(f"{option}: that is --out itself; a sweep resumes from its own folder unasked")
    if (out / EPISODES_FILE).exists() or (out / SWEEP_FILE).exists():
        raise PipelineError(
            f"{option}: --out {out} holds a sweep already; --reuse seeds a new folder (drop it to resume)"
        )
    check_sweep_directory(source, "--reuse")
    planned = {task.key: task.cell.method for task in tasks}
    records = []
    for _, _, record in episode_log(source).scan(repair=False):  # the source is read, never cut
        label = planned.get(record["key"])
        if label is not None:
            records.append({**record, "method": label})
    return records, read_sweep_file(source / SWEEP_FILE).get("runs", [])


def reuse_records(source: Path, out: Path, experiment: Any, tasks: Sequence[EpisodeTask]) -> str:
    """Write ``out``'s episodes.jsonl and sweep.json from ``source``'s episodes of ``tasks`` (module
    docstring): the run lines their records name first, renumbered from 1, then the sweep adds its own.
    Returns the line that says what was taken."""
    records, source_runs = reusable(source, out, tasks)
    if not records:
        return f"--reuse {source}: none of its episodes is one of this plan's (no cell in common)"
    used = sorted({int(r.get("run", 0)) for r in records})
    numbers = {run: k for k, run in enumerate(used, start=1)}
    runs = []
    for run in used:
        line = source_runs[run - 1] if 1 <= run <= len(source_runs) else None
        where = {"reused_from": str(source.resolve()), "run_there": run}
        runs.append({**line, **where} if isinstance(line, dict) else {"lost": f"not in {source}", **where})
    out.mkdir(parents=True, exist_ok=True)
    with sweep_lock(out):
        lines = (
            json.dumps(plain({**r, "run": numbers[int(r.get("run", 0))], "experiment": experiment.name}))
            for r in records
        )
        _write(out / EPISODES_FILE, "".join(f"{line}\n" for line in lines))
        meta = {"experiment": experiment.name, "title": experiment.title, "runs": runs}
        _write(out / SWEEP_FILE, json.dumps(plain(meta), indent=1) + "\n")
    cells = len({r["cell"] for r in records})
    return f"reused {len(records)} episodes of {cells} cell(s) from {source} ({len(runs)} of its runs)"


def _write(path: Path, text: str) -> None:
    """``text`` into ``path`` in one rename, synced: a stop halfway leaves no half file."""
    tmp = path.with_name(path.name + PART_SUFFIX)
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
