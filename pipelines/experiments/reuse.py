"""``crowdmpc sweep --reuse DIR``: a sweep folder given another sweep's episodes of the cells both plans hold,
so that they are not run again.

A cell's key holds everything that defines its episodes (controller, predictor, flocking, coupling, every
setting, margins, world, crowd size, robots: ``Cell.key``), and an episode's key adds its scenario and seed,
so a record of another sweep under a key this plan has is this plan's episode, run. Table III's F cells are
Table II's CMPC cells: a paper-scale Table III ran those 5000 episodes again, or was seeded by hand with Table
II's lines, whose code its table.md then called "unknown". Each record taken keeps its episode as it is, under
this experiment's name, method label and index, and its run's line of the source's sweep.json (code,
settings, cells) comes with it, marked ``reused_from`` and ``run_there``; the sweep then runs the rest as a
resume does. A line the source itself took with --reuse keeps where it points (the sweep that ran those
episodes: their code, config and recordings), so a chain of reuses names their origin in one step. The
reused lines are the code of those episodes, not runs of this sweep: ``config show --from-sweep``,
``--report-only`` and ``review`` read this sweep's own runs (``run_lines.own_runs``).

Taking is a resume of its own: the records are checked first as a resume checks its own (the weights,
margins and crowd the cells plan with now), the run lines are written before the records that name them, and
a sweep stopped halfway takes the rest when the same command runs again (a line already taken is not taken
twice, nor an episode the folder holds). The source is only read; the recordings stay in the mcap folder of
the sweep that made them.
"""

from __future__ import annotations

import contextlib
import os
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipelines.errors import PipelineError, print_note
from pipelines.experiments.cells import Experiment
from pipelines.experiments.log import (
    EPISODES_FILE,
    MCAP_DIR,
    SWEEP_FILE,
    EpisodeLog,
    episode_log,
    mcap_path,
    read_sweep_file,
)
from pipelines.experiments.run_lines import REUSED, is_reused, lost_runs, run_number, write_sweep_file
from pipelines.experiments.tasks import EpisodeTask

if TYPE_CHECKING:
    from pipelines.experiments.checked_calibrations import CheckedInputs


def check_source(source: Path, out: Path) -> None:
    """Before ``out`` is made: ``source`` holds a sweep's log and run lines, neither a link (the files of the
    folder named are read, not others), its sweep.json readable, and is not ``out``."""
    option = f"--reuse {source}"
    for name in (SWEEP_FILE, EPISODES_FILE):
        if (source / name).is_symlink():
            raise PipelineError(
                f"{option}: {source / name} is a symbolic link; --reuse reads a sweep's own files"
            )
        if not (source / name).is_file():
            # a folder or a pipe there exists: "does not exist" sent the user looking for a missing file
            what = "is not a regular file" if (source / name).exists() else "does not exist"
            raise PipelineError(f"{option}: not a sweep folder ({source / name} {what})")
    if out.is_dir() and os.path.samefile(out, source):
        raise PipelineError(f"{option}: that is --out itself; a sweep resumes from its own folder unasked")
    _source_runs(source)  # and read again after its log (``taken``)


def _source_runs(source: Path) -> list[Any]:
    """The run lines of ``source``'s sweep.json; a PipelineError naming it as --reuse's."""
    with _named(source):
        return read_sweep_file(source / SWEEP_FILE, hint="").get("runs", [])


def _source_records(source: Path, progress: bool | None = False) -> Iterator[dict[str, Any]]:
    """The records of ``source``'s log, read and never cut, with a bar when ``progress``; a damaged one a
    PipelineError naming it as --reuse's (editing another sweep's log is not this sweep's to advise)."""
    with _named(source):
        log = episode_log(source, damaged="that sweep's own rerun refuses it too")
        scanned = log.scan_shown(progress, repair=False, name=str(source / EPISODES_FILE))
        yield from (record for _, _, record in scanned)


@contextlib.contextmanager
def _named(source: Path) -> Iterator[None]:
    """A PipelineError of reading ``source`` raised again as --reuse's."""
    try:
        yield
    except PipelineError as exc:
        raise PipelineError(f"--reuse {source}: {exc}") from None


@dataclass(frozen=True)
class Taken:
    """What ``taken`` found: the key of each episode to take, with the run of ``source`` that made it (None:
    unknown), that source's run lines, and the highest run a record of ``out`` names."""

    runs_there: dict[str, int | None]
    source_runs: list[Any]
    last_run: int


def taken(
    source: Path,
    out: Path,
    tasks: Sequence[EpisodeTask],
    *,
    repair: bool = False,
    progress: bool | None = False,
    checked: CheckedInputs | None = None,
) -> Taken:
    """The episodes of ``tasks`` that ``source`` (another sweep's folder) recorded and ``out`` has not. Both
    folders' records are checked as a resume checks its own (the weights, margins and crowd the cells plan
    with now), ``out``'s first, so that a refusal writes nothing; a PipelineError names the file. Held: a key
    and a run number an episode, not the records (those of a 20,000-episode source took 18 KB each).
    ``repair``: cut a torn last line off ``out``'s log (only the sweep holding its lock may), which the
    records taken would otherwise follow. ``progress``: a bar of each log read (None: on a terminal only), of
    100,000 records ~10 s each. ``checked``: the weights and calibration blocks the sweep hands its workers
    (``ResumeChecks``'), which both folders' records are checked against."""
    from pipelines.experiments.resume_checks import ResumeChecks, read_recorded

    check_source(source, out)
    own = read_recorded(out, list(tasks), progress, repair=repair, checked=checked)
    left = {t.key for i, t in enumerate(tasks) if not own.recorded(i)}
    checks = ResumeChecks(source, list(tasks), reused=True, checked=checked)
    there: dict[str, Any] = {}
    for record in _source_records(source, progress):
        if record["key"] in left:  # a key once: the source's scan refuses a second
            checks.add(record)
            there[record["key"]] = run_number(record)
    checks.check()
    runs = _source_runs(source)  # read after its log: the line of a run the source began meanwhile is there
    return Taken({key: _run_there(run, len(runs)) for key, run in there.items()}, runs, own.last_run)


def _run_there(run: int | None, listed: int) -> int | None:
    """The source's run that made a record naming ``run`` (``run_number``): that number (one past the lines
    its sweep.json lists: a lost run, run_lines.lost_runs), or the only run of a sweep.json of ``listed`` = 1
    line (a record from before records kept it); None when unknown."""
    if run is not None and run >= 1:
        return run
    return 1 if listed == 1 else None


def seed_from(
    source: Path,
    out: Path,
    experiment: Experiment,
    tasks: Sequence[EpisodeTask],
    meta: dict[str, Any],
    progress: bool | None = False,
    checked: CheckedInputs | None = None,
) -> dict[str, Any]:
    """Give ``out`` (a sweep folder whose lock the caller holds; ``meta``: its sweep.json, checked to be
    ``experiment``'s) the episodes ``taken`` finds in ``source``: their runs' lines first, in sweep.json,
    then their records, relabelled, in episodes.jsonl. Returns sweep.json as written; says on stderr what it
    took. ``progress``, ``checked``: ``taken``'s."""
    found = taken(source, out, tasks, repair=True, progress=progress, checked=checked)
    if not found.runs_there:
        print_note(f"--reuse {source}: none of its episodes is one of this plan's left to run")
        return meta
    runs = meta.setdefault("runs", [])
    numbers = {(r.get(REUSED), r.get("run_there")): k for k, r in enumerate(runs, start=1) if is_reused(r)}
    listed = len(runs)
    lost = max(0, found.last_run - listed)  # the lost runs' numbers come first: records name them
    added: list[dict[str, Any]] = []
    number_of: dict[int | None, int] = {}
    for there in sorted(set(found.runs_there.values()), key=lambda run: (run is None, run or 0)):
        line = found.source_runs[there - 1] if there is not None and there <= len(found.source_runs) else None
        if not isinstance(line, dict):  # its code is unknown, as a lost run's is (run_lines.is_lost)
            line = {"lost": f"no line of {source / SWEEP_FILE} names the run of its episodes"}
        origin = _origin(source, there, line)
        if origin not in numbers:
            added.append({**line, REUSED: origin[0], "run_there": origin[1]})
            numbers[origin] = listed + lost + len(added)
        number_of[there] = numbers[origin]
    # the run that began is the sweep's own, after the lines taken (they named run listed + lost + 1)
    runs.extend(lost_runs(out, listed, found.last_run, began=listed + lost + len(added) + 1))
    runs.extend(added)
    meta["experiment"], meta["title"] = experiment.name, experiment.title
    write_sweep_file(out / SWEEP_FILE, meta)
    by_key = {task.key: task for task in tasks if task.key in found.runs_there}
    run_of = {key: number_of[there] for key, there in found.runs_there.items()}
    _append(out / EPISODES_FILE, source, by_key, run_of, progress)
    folders = {key: _folder(source, runs[number - 1][REUSED]) for key, number in run_of.items()}
    cells = len({task.cell.key for task in by_key.values()})
    print_note(
        f"reused {len(by_key)} episode(s) of {cells} cell(s) from {source} ({len(set(run_of.values()))} of "
        f"its runs){_recordings(by_key, folders)}"
    )
    return meta


def _origin(source: Path, there: int | None, line: dict[str, Any]) -> tuple[str, int | None]:
    """The sweep folder and run that made the episodes of run ``there`` of ``source`` (its ``line``): that
    run, or where a line ``source`` itself took with --reuse points, so that a chain of reuses names the
    sweep that ran them (its config, its recordings) in one step."""
    if is_reused(line):
        return line[REUSED], line.get("run_there")
    return str(source.resolve()), there


def _folder(source: Path, where: str) -> Path:
    """``where`` (a reused line's absolute folder) as the user named it when it is ``source``."""
    return source if where == str(source.resolve()) else Path(where)


def _recordings(tasks: dict[str, EpisodeTask], folders: dict[str, Path]) -> str:
    """ "; N of their recordings stay in DIR/mcap[, M in OTHER/mcap]" for the episodes ``tasks`` taken, each
    kept in ``folders``' sweep (the one that ran it), or nothing when none was recorded."""
    kept = Counter(folders[key] for key, task in tasks.items() if mcap_path(folders[key], task).is_file())
    if not kept:
        return ""
    (folder, count), *more = kept.items()
    return f"; {count} of their recordings stay in {folder / MCAP_DIR}" + "".join(
        f", {n} in {f / MCAP_DIR}" for f, n in more
    )


def _append(
    path: Path,
    source: Path,
    tasks: dict[str, EpisodeTask],
    run_of: dict[str, int],
    progress: bool | None = False,
) -> None:
    """The records of ``source`` of ``tasks``' keys, under their labels and with ``run_of``'s numbers, as the
    log's last lines, read and written a record at a time (``EpisodeLog.extend``). A source whose records
    taken went missing between its two reads (edited: a log is only appended to) is refused."""
    written: set[str] = set()

    def relabelled() -> Iterator[dict[str, Any]]:
        for record in _source_records(source, progress):
            task = tasks.get(record["key"])
            if task is not None and task.key not in written:
                written.add(task.key)
                label = {"experiment": task.experiment, "method": task.cell.method, "index": task.index}
                yield {**record, **label, "run": run_of[task.key]}

    EpisodeLog(path).extend(relabelled())
    if len(written) != len(tasks):
        raise PipelineError(
            f"--reuse {source}: its episodes changed while they were read; run the sweep again"
        )
