"""``crowdmpc review DIR``: a folder's recordings read one at a time (what cannot be read named on stderr),
then a table and aggregate per set-up, into the review's report (pipelines.commands.review runs it)."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipelines.commands.review_notes import (
    deeper_note,
    subfolders_note,
    unread_below,
    warn,
    warn_failures_only,
    warn_mixed_code,
    warn_repeats,
)
from pipelines.errors import PipelineError, one_line, print_note

if TYPE_CHECKING:
    from pipelines.logs.digest import RunDigest


def read_folder(
    folder: Path, report: dict[str, Any], check: bool, show: bool | None = None
) -> tuple[list[RunDigest], int]:
    """Every readable recording of ``folder``, digested (``pipelines.logs.digest``: read one at a time, the
    messages let go), and how many were not readable; a line on stderr for each left out. ``show``: the bar
    of the files read (None: on a terminal only; False: --no-progress)."""
    from tqdm import tqdm

    from pipelines.logs.digest import digest
    from pipelines.logs.reader import find_recordings, read_recording
    from predictors.progress import progress_bar

    try:
        paths, unfinished = find_recordings(folder)
    except PipelineError as exc:  # nothing within two levels: say what lies deeper (a folder of sweeps)
        raise PipelineError(f"{exc}{deeper_note(folder)}") from None
    # its own files read: those of its subfolders are not (never mixed), which must not pass unsaid
    unread = unread_below(folder) if any(p.parent == folder for p in paths + unfinished) else 0
    for path in unfinished:
        print_note(
            f"crowdmpc review: warning: skipping {path}: unfinished (its run was killed or is still "
            f"writing); `crowdmpc review {shlex.quote(str(path))}` reads what it holds"
        )
    runs, unreadable = [], {}
    # a bar on a terminal only (disable=None): a sweep's thousands of files take minutes
    for path in progress_bar(paths, desc=f"reading {folder}", unit="file", leave=False, show=show):
        try:
            runs.append(digest(read_recording(path), check))
        except PipelineError as exc:
            unreadable[str(path)] = str(exc)
            tqdm.write(one_line(f"crowdmpc review: unreadable: {exc}"), file=sys.stderr)  # beside the bar
    report.update(unreadable=unreadable, unfinished=[str(p) for p in unfinished])
    note = subfolders_note(folder, unread) if unread else ""
    if not runs:
        raise PipelineError(
            f"no readable recording in {folder} ({len(unreadable)} unreadable, {len(unfinished)} unfinished)"
            + (f"; {note}" if note else "")
        )
    if note:
        warn(f"{folder}: {note}")
    return runs, len(unreadable)


def review_folder(
    folder: Path, report: dict[str, Any], check: bool, show: bool | None = None
) -> tuple[list[RunDigest], int]:
    """``review DIR``: every readable recording's summary, then a table and aggregate per set-up (a note, not
    a warning, names several: a sweep's cells are so by design), into ``report``; the runs and the number of
    unreadable files."""
    from pipelines.logs.identity import RUN_IDENTITY
    from pipelines.logs.review import count
    from pipelines.logs.run_tables import aggregate_table, setups_table
    from pipelines.logs.setups import drop_repeats, group_parts, groups, named_settings, short_names

    runs, n_unreadable = read_folder(folder, report, check, show)
    warn_failures_only(folder, runs)
    report["runs"] = [run.summary for run in runs]
    setups = groups(runs)
    repeats = [drop_repeats(setup) for setup in setups]
    named = named_settings(setups)
    parts = [group_parts(setup, named) for setup in setups]
    names = [", ".join(p) for p in parts]
    if len(setups) > 1:
        print_note(
            f"crowdmpc review: note: {folder} holds runs of {len(setups)} different set-ups "
            f"({'; '.join(names)}): one aggregate for each, none over all"
        )
    report["groups"] = []
    for setup, name, repeated in zip(setups, names, repeats, strict=True):
        members = [run.summary for run in setup.members]
        warn_repeats(folder, name, repeated)
        warn_mixed_code(folder, name, members)
        table, totals = aggregate_table(members, [run.solve_times_s for run in setup.members], root=folder)
        if len(setups) > 1:
            print(f"== {name}: {count(len(setup.members), 'run')} ==")
        print(table + ("\n" if len(setups) > 1 else ""))
        identity = setup.identity or {}
        report["groups"].append(
            {"name": name}
            | {k: members[0][k] for k in RUN_IDENTITY}
            | {"settings": {k: identity.get(k) for k in named}}
            | {"files": [run.file for run in setup.members], "repeats": repeated, "totals": totals}
        )
    if len(setups) == 1:  # as before the folder held several: the one set-up's totals at the top
        report["totals"] = report["groups"][0]["totals"]
    else:
        side_by_side = setups_table(short_names(parts), [group["totals"] for group in report["groups"]])
        print(f"== {count(len(setups), 'set-up')} side by side ==\n{side_by_side}")
    return runs, n_unreadable


def recordings_or_none(folder: Path) -> list[Path]:
    """The recordings a review of ``folder`` would read (none where it finds none), to name one."""
    from pipelines.logs.reader import find_recordings

    try:
        return find_recordings(folder)[0]
    except PipelineError:
        return []
