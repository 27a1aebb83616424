"""The notes under table.md's table of a sweep: the code behind its episodes, as sweep.json's runs recorded
it (``code_note``), and the planned episodes it does not count (``not_counted_note``)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Collection
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipelines.experiments.run_lines import runs_named
from predictors.text_table import counted

if TYPE_CHECKING:
    from pipelines.experiments.tasks import Cell, EpisodeTask


def code_note(out: Path, used: Collection[int | None] | None = None) -> str:
    """table.md's line naming the code behind its episodes, as sweep.json's runs recorded it: "Code: commit
    0123456789ab, crowdmpc 0.1.0, Python 3.11.7, CasADi 3.8.2, torch 2.13.0+cpu, numpy 2.4.6." (each
    version of the code once, in the order the runs met them); "" without a sweep.json. The table alone had
    said nothing of it, and a copy of it in a paper's supplement could not be traced to its code. ``used``:
    the runs (their records' ``run``) that made the tabulated episodes, whose code alone it names (every
    run's had named code that made none of them); None, or a record older than its run number: every run."""
    from pipelines.experiments.log import SWEEP_FILE, read_sweep_file

    if not (out / SWEEP_FILE).is_file():
        return ""
    runs = read_sweep_file(out / SWEEP_FILE).get("runs", [])
    runs = runs if used is None else runs_named(runs, used)
    shown = list(dict.fromkeys(_code_text(run) for run in runs))
    if len(shown) <= 1:
        return f"Code: {shown[0]}." if shown else ""
    return f"Code: {len(shown)} versions, in the order the sweep's runs used them: " + "; ".join(shown) + "."


def _code_text(run: Any) -> str:
    """A run line's recorded code (``pipelines.version.code_identity``, with its plugins) in one line; that
    of a run sweep.json no longer listed (``run_lines.lost_runs``) is unknown."""
    from pipelines.experiments.run_lines import is_lost, is_reused
    from pipelines.version import dirty_text, no_commit_text, versions_text

    if is_lost(run):  # a line --reuse took says which sweep's file lacks it
        return f"unknown ({run['lost']})" if is_reused(run) else "unknown (a run sweep.json no longer listed)"
    code = run.get("code") if isinstance(run, dict) else None
    if not isinstance(code, dict):
        return "not recorded (a run from before the code was)"
    commit = code.get("commit")
    # none from an installed wheel or a folder without .git (a `ray job submit` copy): said, not "commit None"
    dirty = dirty_text(code.get("dirty"), code.get("diff_sha256"))
    if commit:
        parts = [f"commit {str(commit)[:12]}{dirty}", *versions_text(code)]
    else:  # as compare names it
        parts = [no_commit_text(code) or "no git commit"]
    plugins = code.get("plugins")
    if isinstance(plugins, dict):
        parts += [f"plugin {spec} {str(sha)[:12]}" for spec, sha in sorted(plugins.items())]
    return ", ".join(parts)


NOT_COUNTED_NAMED = 8  # cells named in table.md's note of episodes not recorded; the rest counted


def not_counted_note(cells: tuple[Cell, ...], tasks: list[EpisodeTask], recorded: dict[str, int]) -> str:
    """table.md's line for the tabulated cells with planned episodes not recorded ("" when none): an episode
    that raised or ran past --episode-timeout (errors.jsonl) is in no rate, so a cell whose slow episodes
    timed out had its rates of the quick ones, or no column at all, under "N episodes per cell"."""
    planned = Counter(task.cell.key for task in tasks)
    short = [
        f"{c.method} at {counted(c.n_humans, 'human')} "
        f"{planned[c.key] - recorded.get(c.key, 0)} of {planned[c.key]}"
        for c in cells
        if recorded.get(c.key, 0) < planned.get(c.key, 0)
    ]
    if not short:
        return ""
    if len(short) > NOT_COUNTED_NAMED:  # a sweep stopped early: every cell short
        short = [*short[:NOT_COUNTED_NAMED], f"{len(short) - NOT_COUNTED_NAMED} more cells"]
    return (
        f"Not counted, planned episodes not recorded: {'; '.join(short)} (each raised or ran past "
        "--episode-timeout, in errors.jsonl, or has not run yet; a rerun runs them): the rates are of the "
        "recorded episodes, and a cell with none has no column."
    )
