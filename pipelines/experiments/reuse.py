"""``crowdmpc sweep --reuse DIR``: a sweep folder given another sweep's episodes of the cells both plans hold,
so that they are not run again.

A cell's key holds everything that defines its episodes (controller, predictor, flocking, coupling, every
setting, margins, world, crowd size, robots: ``Cell.key``), and an episode's key adds its scenario and seed,
so a record of another sweep under a key this plan has is this plan's episode, run. Table III's F cells are
Table II's CMPC cells: a paper-scale Table III ran those 5000 episodes again, or was seeded by hand with Table
II's lines, whose code its table.md then called "unknown". Each record taken keeps its episode as it is, under
this experiment's name, method label and index, and its run's line of the source's sweep.json (code,
settings, cells) comes with it, marked ``reused_from`` and ``run_there``; the sweep then runs the rest as a
resume does. The reused lines are the code of those episodes, not runs of this sweep: ``config show
--from-sweep``, ``--report-only`` and ``review`` read this sweep's own runs (``run_lines.own_runs``).

Taking is a resume of its own: the records are checked first as a resume checks its own (the weights,
margins and crowd the cells plan with now), the run lines are written before the records that name them, and
a sweep stopped halfway takes the rest when the same command runs again (a line already taken is not taken
twice, nor an episode the folder holds). The source is only read; its recordings stay in its mcap folder.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pipelines.errors import PipelineError, writes_named
from pipelines.experiments.cells import Experiment
from pipelines.experiments.log import (
    EPISODES_FILE,
    MCAP_DIR,
    SWEEP_FILE,
    check_sweep_directory,
    episode_log,
    read_sweep_file,
)
from pipelines.experiments.run_lines import REUSED, is_reused, lost_runs, write_sweep_file
from pipelines.experiments.tasks import EpisodeTask
from pipelines.plain_json import plain


def reusable(
    source: Path, out: Path, tasks: Sequence[EpisodeTask], *, repair: bool = False
) -> tuple[list[dict[str, Any]], list[Any], int]:
    """The records of ``source`` (another sweep's folder) that are episodes of ``tasks`` not recorded in
    ``out``, relabelled for them and checked as a resume checks its own; the source's run lines; the highest
    run a record of ``out`` names. A PipelineError naming ``source`` for a folder that is no sweep, is
    ``out``, or whose episodes were made with other weights, margins or crowds than the cells plan with now.
    ``repair``: cut a torn last line off ``out``'s log (only the sweep holding its lock may), which the
    records taken would otherwise follow."""
    from pipelines.experiments.resume_checks import ResumeChecks

    option = f"--reuse {source}"
    for name in (SWEEP_FILE, EPISODES_FILE):
        if not (source / name).is_file():
            raise PipelineError(f"{option}: not a sweep folder ({source / name} does not exist)")
    if out.is_dir() and os.path.samefile(out, source):
        raise PipelineError(f"{option}: that is --out itself; a sweep resumes from its own folder unasked")
    check_sweep_directory(source, "--reuse")
    runs = read_sweep_file(source / SWEEP_FILE).get("runs", [])
    have, last_run = set(), 0
    for _, _, record in episode_log(out).scan(repair=repair):
        have.add(record["key"])
        last_run = max(last_run, _run_there(record, 0) or 0)
    planned = {task.key: task for task in tasks if task.key not in have}
    checks = ResumeChecks(source, list(tasks), reused=True)
    records = []
    for _, _, record in episode_log(source).scan(repair=False):  # the source is read, never cut
        task = planned.pop(record["key"], None)  # a key once: the source's scan refuses a second
        if task is not None:
            checks.add(record)
            label = {"experiment": task.experiment, "method": task.cell.method, "index": task.index}
            records.append({**record, **label, "run": _run_there(record, len(runs))})
    checks.check()
    return records, runs, last_run


def _run_there(record: dict[str, Any], listed: int) -> int | None:
    """The run that made ``record``: its ``run`` (one past the lines sweep.json lists: a lost run,
    run_lines.lost_runs), or the only run of a sweep.json of ``listed`` = 1 line (a record from before records
    kept it); None when unknown."""
    run = record.get("run")
    if isinstance(run, int) and not isinstance(run, bool) and run >= 1:
        return run
    return 1 if listed == 1 else None


def seed_from(
    source: Path, out: Path, experiment: Experiment, tasks: Sequence[EpisodeTask], meta: dict[str, Any]
) -> dict[str, Any]:
    """Give ``out`` (a sweep folder whose lock the caller holds; ``meta``: its sweep.json, checked to be
    ``experiment``'s) the episodes ``reusable`` takes from ``source``: their runs' lines first, in
    sweep.json, then the records naming them in episodes.jsonl. Returns sweep.json as written; says on
    stderr what it took."""
    records, source_runs, last_run = reusable(source, out, tasks, repair=True)
    if not records:
        print(f"--reuse {source}: none of its episodes is one of this plan's left to run", file=sys.stderr)
        return meta
    runs = meta.setdefault("runs", [])
    runs.extend(lost_runs(out, len(runs), last_run))  # before new numbers are taken
    where = str(source.resolve())
    numbers = {(r.get(REUSED), r.get("run_there")): k for k, r in enumerate(runs, start=1) if is_reused(r)}
    for record in records:
        there = record["run"]
        if (where, there) not in numbers:
            line = source_runs[there - 1] if there is not None and there <= len(source_runs) else None
            if not isinstance(line, dict):  # its code is unknown, as a lost run's is (run_lines.is_lost)
                line = {"lost": f"no line of {source / SWEEP_FILE} names the run of its episodes"}
            runs.append({**line, REUSED: where, "run_there": there})
            numbers[(where, there)] = len(runs)
        record["run"] = numbers[(where, there)]
    meta["experiment"], meta["title"] = experiment.name, experiment.title
    write_sweep_file(out / SWEEP_FILE, meta)
    _append(out / EPISODES_FILE, records)
    cells = len({r["cell"] for r in records})
    kept = f"; their recordings stay in {source / MCAP_DIR}" if (source / MCAP_DIR).is_dir() else ""
    print(
        f"reused {len(records)} episode(s) of {cells} cell(s) from {source} "
        f"({len({r['run'] for r in records})} of its runs){kept}",
        file=sys.stderr,
    )
    return meta


def _append(path: Path, records: list[dict[str, Any]]) -> None:
    """The records as the log's last lines, synced once (a record at a time, as a sweep appends them, took a
    disk sync each): a stop halfway leaves whole lines and at most a torn last one, which a resume cuts."""
    lines = "".join(json.dumps(plain(r), allow_nan=False, separators=(",", ":")) + "\n" for r in records)
    with writes_named(path), open(path, "ab") as f:
        f.write(lines.encode())
        f.flush()
        os.fsync(f.fileno())
