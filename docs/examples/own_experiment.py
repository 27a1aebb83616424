"""An experiment of your own, swept from Python: a table no shipped experiment holds, resumable as a sweep.

The shipped experiments (``crowdmpc sweep --experiment ...``) are ``pipelines.experiments.cells.Experiment``
values: methods (a column label and a ``ControllerSpec``) times numbers of humans, each method optionally
under a ``World`` of its own (profile, visibility, a sensor range: ``method_worlds``) and with a team of its
own (``method_robots={"ORCA 6": 6}``, else the sweep's ``n_robots``). Here: CMPC with the constant-velocity
predictor given every human, behind a 3 m sensor, and behind it with fixed 0.1 m margins, next to ORCA,
at 5 humans. ``run_sweep`` runs what ``OUT/episodes.jsonl`` lacks (run it again with more episodes and it
extends the table), and ``write_report`` writes the table, CSVs and plots ``crowdmpc sweep`` writes.

    CROWDMPC_DATA=../shared/data .venv/bin/python docs/examples/own_experiment.py runs/mine --episodes 20
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pipelines.commands import check_writable
from pipelines.errors import PipelineError
from pipelines.experiments.cells import Experiment
from pipelines.experiments.log import episode_log
from pipelines.experiments.report import write_report
from pipelines.experiments.sweep import SweepConfig, run_sweep
from pipelines.experiments.tasks import World
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.margins import MarginSpec


def experiment() -> Experiment:
    cmpc = ControllerSpec("cmpc", "constant_velocity")
    # one margin per step of Table I's horizon of 4 (the margins' own check names it if another is set)
    fixed = ControllerSpec("cmpc", "constant_velocity", margins=MarginSpec("fixed", values=(0.1,) * 4))
    sensed = World().sensing(3.0)
    return Experiment(
        name="sensed_margins",  # sweep.json records it: one experiment per folder
        title="CMPC given every human, behind a 3 m sensor, and behind it with 0.1 m margins; ORCA",
        methods=(("full", cmpc), ("3 m", cmpc), ("3 m + 0.1 m", fixed), ("ORCA", ControllerSpec("orca"))),
        humans=(5,),
        method_worlds={"3 m": sensed, "3 m + 0.1 m": sensed},
    )


def main(out: str, episodes: int, workers: int = 2, backend: str = "auto") -> None:
    table = experiment()
    config = SweepConfig(table, Path(out), episodes, workers=workers, backend=backend, progress=False)
    outcome = run_sweep(config)
    print(f"{outcome.ran} episodes run, {outcome.already_done} already there, {len(outcome.errors)} errors")
    cells = table.cells(config.humans, config.n_robots)
    records = episode_log(Path(out)).load(repair=False)  # repairs are for the sweep that holds the lock
    report = write_report(Path(out), table, cells, list(records.values()))
    print(report.markdown)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="the sweep folder (created, or extended)")
    parser.add_argument("--episodes", type=int, default=20, help="episodes per cell")
    args = parser.parse_args()
    try:  # a folder that cannot be made (/proc/x) was a FileNotFoundError traceback from the sweep
        check_writable(Path(args.out), "argument out", directory=True)
    except PipelineError as exc:
        parser.error(str(exc))
    main(args.out, args.episodes)
