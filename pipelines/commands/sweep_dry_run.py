"""What ``crowdmpc sweep --dry-run`` prints: the planned cells and, over a folder that holds a log (a resume's
preview), how many of each cell's episodes it records and how many a resume would run."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pipelines.commands.sweep_predictors import PlanModels
    from pipelines.experiments.sweep_config import SweepConfig
    from pipelines.experiments.tasks import Cell, EpisodeTask


def print_plan(
    config: SweepConfig,
    cells: Sequence[Cell],
    tasks: list[EpisodeTask],
    reuse: Path | None,
    models: PlanModels | None = None,
) -> None:
    """The cells of the plan, a line each; a folder's sweep.json and log read as the resume reads them
    (``sweep_meta``, ``read_recorded``, which refuse what the resume would), and the episodes ``--reuse``
    would take.
    ``models``: the plan's checks' reads, whose weights and calibration blocks the records are checked
    against, as the run checks them (None: read again)."""
    from pipelines.experiments.log import EPISODES_FILE
    from pipelines.experiments.resume_checks import read_recorded
    from pipelines.experiments.sweep import sweep_meta
    from predictors.text_table import counted

    out, experiment = Path(config.out), config.experiment
    # the run refuses a sweep.json it cannot read, or of another experiment, before any episode: a preview
    # that passed it said "a resume runs N" of a folder the resume refuses
    sweep_meta(out, config)
    print(f"{experiment.title}: {len(cells)} cells x {config.episodes_per_cell} episodes = {len(tasks)}")
    log = out / EPISODES_FILE
    checked = None if models is None else models.checked()
    done: Counter[str] | None = None  # recorded episodes by cell key; None: no log, no column
    if log.is_file():
        recorded = read_recorded(out, tasks, config.progress, checked=checked)
        done = Counter(task.cell.key for i, task in enumerate(tasks) if recorded.recorded(i))
    taken = 0
    if reuse is not None:
        from pipelines.experiments.reuse import taken as reused

        taken = len(reused(reuse, out, tasks, progress=config.progress, checked=checked).runs_there)
    width = max(22, *(len(cell.method) for cell in cells))  # --vary's labels are longer
    digits = len(str(config.episodes_per_cell))
    crowds = {cell.key: counted(cell.n_humans, "human") for cell in cells}
    crowd_width = max(map(len, crowds.values()))  # "1 human" beside "5 humans": the columns stay in line
    for cell in cells:
        column = "" if done is None else f"{done[cell.key]:>{digits}}/{config.episodes_per_cell} recorded  "
        print(f"  {cell.method:>{width}}  {crowds[cell.key]:<{crowd_width}}  {column}{cell.key}")
    if done is not None:
        total = sum(done.values())
        print(
            f"{total} of {len(tasks)} planned episodes recorded in {log}; a resume "
            + (f"takes {taken} with --reuse and " if reuse is not None else "")
            + f"runs {len(tasks) - total - taken}"
        )
    if reuse is not None:
        print(f"--reuse: {taken} of them to take from {reuse}")
