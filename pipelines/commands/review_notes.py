"""The warnings of ``crowdmpc review`` (one line each on stderr) and the notes its errors add: what a review
read that does not mean what its table seems to say (a selection of episodes, two codebases pooled, copies of
one episode, another crowd), and the recordings of a folder that it did not read."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from pipelines.errors import print_note
from predictors.text_table import counted

if TYPE_CHECKING:
    from pipelines.logs.digest import RunDigest

WARNING: Final = "crowdmpc review: warning:"
# How far below a folder an error looks for recordings the review does not read (a folder of two sweeps:
# DIR/a/mcap/CELL/*.mcap is three levels down), and how many folders it opens at most: cheap on any tree.
DEEPEST_LEVEL: Final = 6
MAX_FOLDERS_OPENED: Final = 2000
MAX_FOLDERS_NAMED: Final = 4
# What the subfolders of a sweep's failed episodes mean, said where the review's rates would mislead.
_FAILURES_ONLY: Final = (
    "(sweep --record failures: not every robot arrived, or a robot came within 0.8 m of a human), so the "
    "rates below are over those, not the sweep's"
)


def warn(text: str) -> None:
    print_note(f"{WARNING} {text}")


def warn_failures_only(folder: Path, runs: list[RunDigest]) -> None:
    """Warn when the runs reviewed are a sweep's failed episodes only (``--record failures``): rates over
    them are over a selection (a sweep with 19 collisions in 20 episodes reviewed as "collision 100.0 %
    (19/19)"), not the sweep's. Said by the sweep.json above ``folder`` (its DIR, DIR/mcap or DIR/mcap/CELL)
    where there is one, else, once for the folder, by the files' own "run" metadata (recordings copied away
    from their sweep, or reviewed from a folder above it)."""
    if _sweep_kept_failures(folder):
        return
    kept = [run for run in runs if run.record_policy == "failures"]
    if kept:
        warn(
            f"{len(kept)} of the {len(runs)} recordings in {folder} (e.g. {kept[0].file}) are a sweep's "
            f"failed episodes only {_FAILURES_ONLY}: the sweep's table.md and cells.csv give those"
        )


def _sweep_kept_failures(folder: Path) -> bool:
    """Whether the sweep whose recordings ``folder`` is kept only the failed episodes of some run, warned."""
    from pipelines.errors import PipelineError
    from pipelines.experiments.log import SWEEP_FILE, read_sweep_file, sweep_of_recordings
    from pipelines.experiments.run_lines import is_reused

    here = folder.resolve()
    sweep = here if (here / SWEEP_FILE).is_file() else sweep_of_recordings(here, SWEEP_FILE)
    if sweep is None:
        return False
    try:
        runs = read_sweep_file(sweep / SWEEP_FILE).get("runs", [])
    except PipelineError:  # not ours to judge here: the review reads the recordings, not the sweep
        return False
    # a run --reuse took episodes of kept its recordings in its own folder (pipelines.experiments.reuse)
    if "failures" not in {_record_policy(run) for run in runs if not is_reused(run)}:
        return False
    warn(
        f"{sweep} kept the recordings of its failed episodes only {_FAILURES_ONLY}: its table.md and "
        "cells.csv give those"
    )
    return True


def _record_policy(run: object) -> object:
    """What one run of sweep.json recorded (its config's ``sweep.record``); None where it does not say."""
    for key in ("config", "sweep", "record"):
        run = run.get(key) if isinstance(run, dict) else None
    return run


def warn_mixed_code(folder: Path, name: str, members: list[dict[str, Any]]) -> None:
    """Warn when one set-up's runs were recorded by different code: other commits, a commit with and
    without uncommitted changes ("+dirty"), other plugin files, or some by code that recorded none (before
    4a16d16): its aggregate pools two codebases' results, as a sweep resumed by other code says."""
    from pipelines.logs.review import commit_shown, plugins_shown

    commits = {
        _commit_named(commit_shown(m))
        + (f" with plugins {plugins_shown(m)}" if plugins_shown(m) else ""): None
        for m in members
    }
    if len(commits) > 1:
        warn(
            f"{folder} holds runs recorded by different code ({', '.join(commits)}) pooled in the aggregate "
            f"of {name}; record them again with one version to compare like with like"
        )


def _commit_named(commit: str | None) -> str:
    return f"commit {commit}" if commit is not None else "commit not recorded"


def warn_repeats(folder: Path, name: str, repeats: Mapping[str, str]) -> None:
    """Warn that copies of one episode were counted once (``pipelines.logs.setups.drop_repeats``)."""
    if repeats:
        left_out, kept = next(iter(repeats.items()))
        warn(
            f"{folder} holds {counted(len(repeats), 'repeat')} of episodes of {name} (same "
            "scenario, seed and code), "
            f"left out so that each episode counts once: e.g. {left_out} repeats {kept}"
        )


def unread_below(folder: Path) -> int:
    """The recordings one and two levels below ``folder`` that its review does not read, since it holds
    files of its own (a folder is reviewed as it is, never mixed with its subfolders')."""
    from pipelines.logs.reader import FOLDER_LEVELS

    return sum(1 for pattern in FOLDER_LEVELS[1] for _ in folder.glob(pattern))


def subfolders_note(folder: Path, n: int) -> str:
    return (
        f"its subfolders hold {counted(n, 'recording')}, not read with {folder}'s own files: review each "
        "subfolder"
    )


def deeper_note(folder: Path) -> str:
    """What lies deeper than the two levels a folder's review reads (a folder of two sweeps), looked for
    breadth first, at most ``DEEPEST_LEVEL`` levels down and ``MAX_FOLDERS_OPENED`` folders opened; "" when
    nothing is found."""
    found: dict[str, int] = {}  # folder one level below -> recordings found under it
    level, opened = [(folder, "")], 0
    for depth in range(1, DEEPEST_LEVEL + 1):
        below: list[tuple[Path, str]] = []
        for path, top in level:
            if opened >= MAX_FOLDERS_OPENED:
                break
            opened += 1
            try:
                entries = list(os.scandir(path))
            except OSError:
                continue
            for entry in entries:
                if entry.is_dir(follow_symlinks=False):
                    below.append((Path(entry.path), top or entry.name))
                elif depth > 3 and entry.name.endswith(".mcap"):
                    found[top] = found.get(top, 0) + 1
        level = below
    if not found:
        return _unrecorded_sweep(folder)
    names = [str(folder / top) for top in sorted(found)]
    shown = ", ".join(names[:MAX_FOLDERS_NAMED]) + (", ..." if len(names) > MAX_FOLDERS_NAMED else "")
    n = sum(found.values())
    return f"; deeper folders hold {counted(n, 'recording')} (under {shown}): review each of those folders"


def _unrecorded_sweep(folder: Path) -> str:
    """A sweep's folder without recordings: a sweep writes them only when asked (``--record``)."""
    from pipelines.experiments.log import SWEEP_FILE

    if not (folder / SWEEP_FILE).is_file():
        return ""
    return (
        "; it is a sweep's, which records episodes only with `sweep --record all|failures` (its table.md and "
        "cells.csv hold its results)"
    )


def warn_different_crowds(a: Mapping[str, Any], b: Mapping[str, Any]) -> None:
    """Warn when ``review A --compare B`` sets two episodes of different crowds side by side (another
    scenario, seed or number of humans): their metrics differ by the crowd, not only by the controller."""
    named = {"scenario": "scenario", "seed": "seed", "n_humans": "humans"}
    known = {key: word for key, word in named.items() if a[key] is not None and b[key] is not None}
    differ = [f"{word} {a[key]} vs {b[key]}" for key, word in known.items() if a[key] != b[key]]
    if differ:
        warn(
            f"{a['file']} and {b['file']} are episodes of different crowds ({', '.join(differ)}): their "
            "metrics differ by the crowd too; compare recordings of one scenario and seed"
        )
        return
    # a value a file does not record (its metadata lost or cut off) was shown as None, the crowds as different
    lacking = [
        f"{run['file']} records no {', '.join(words[:-1])}{' or ' * (len(words) > 1)}{words[-1]}"
        for run in (a, b)
        if (words := [word for key, word in named.items() if run[key] is None])
    ]
    if lacking:
        warn(
            f"{a['file']} and {b['file']} may be episodes of different crowds ({'; '.join(lacking)}): their "
            "metrics may differ by the crowd too"
        )
