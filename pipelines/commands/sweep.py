"""``crowdmpc sweep``: run an experiment's cells (Tables II/III, ablations) resumably, and tabulate them."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from pipelines.commands import check_writable, humans_list
from pipelines.commands.output_paths import without_missing_parents
from pipelines.commands.simulate_checks import check_mpc_solvable
from pipelines.commands.sweep_checks import check_plan, noted_models
from pipelines.commands.sweep_first_episodes import check_first_episodes
from pipelines.commands.sweep_help import EPILOG
from pipelines.commands.sweep_jit import check_compile_cache, choose_jit
from pipelines.commands.sweep_options import add_execution_options, add_method_options, config_options
from pipelines.commands.sweep_plan import check_iterations_recorded, check_world, configured_experiment
from pipelines.errors import PipelineError, SweepStopped

if TYPE_CHECKING:
    from collections.abc import Iterable

    from pipelines.commands.sweep_log_read import LogRead
    from pipelines.commands.sweep_predictors import PlanModels
    from pipelines.config import RunConfig
    from pipelines.experiments.cells import Cell
    from pipelines.experiments.sweep_config import SweepConfig


def register(subparsers: argparse._SubParsersAction) -> None:
    from crowdsim.world import PAPER_ROBOTS
    from pipelines.commands.config import add_config_options
    from pipelines.config.schema import key_default
    from pipelines.experiments.backends import BACKENDS
    from pipelines.experiments.cells import EXPERIMENTS, PAPER_EPISODES_PER_CELL

    p = subparsers.add_parser(
        "sweep",
        help="run an experiment's episodes in parallel (resumable) and write its table and plots",
        description="Run the cells of an experiment, append every finished episode to DIR/episodes.jsonl, "
        "and write a CSV, a Markdown table beside the paper's figures, and plots.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    # Defaults are None: an option given overrides the config (file, --set), whose defaults are these.
    study = "the study to run: its cells and methods (required, here or as [sweep] experiment)"
    p.add_argument("--experiment", choices=sorted(EXPERIMENTS), help=study)
    p.add_argument(
        "--episodes-per-cell",
        type=int,
        metavar="N",
        help="episodes per cell, circle and perpendicular crossings in turn, the circle first (even N: half "
        f"of each) (default {PAPER_EPISODES_PER_CELL}, the paper's)",
    )
    p.add_argument(
        "--workers", type=int, metavar="K", help="parallel workers (default: the CPUs this process may use)"
    )
    p.add_argument(
        "--ray-address",
        metavar="ADDR",
        help="run on this Ray cluster: the address `ray start --head` printed (HOST:6379) or "
        "ray://HOST:10001 (needs the [cluster] extra); --workers actors, at most one per free CPU there "
        "(default: $RAY_ADDRESS where set, as ray.init reads it; else, or RAY_ADDRESS=local, a local Ray)",
    )
    p.add_argument(
        "--backend",
        choices=BACKENDS,
        help="where the episodes run: auto (default): Ray when installed, else a local process pool; "
        "inline: in this process",
    )
    sizes = "humans per episode, a crowd size a cell (default: the experiment's)"
    p.add_argument("--humans", type=humans_list, metavar="5,6,7", help=sizes)
    p.add_argument("--robots", type=int, help=f"robots per episode (default {PAPER_ROBOTS})")
    p.add_argument("--seed", type=int, help=f"first crowd's seed (default {key_default('sweep', 'seed')})")
    add_method_options(p)
    add_execution_options(p)
    add_config_options(p)
    p.set_defaults(func=run, parser_error=p.error)


def run(args: argparse.Namespace) -> int:
    from pipelines.commands.sweep_log_read import LogRead
    from pipelines.commands.sweep_report import recorded_plan, report, report_stopped
    from pipelines.commands.sweep_run import INTERRUPTED, run_cells
    from pipelines.experiments.log import EPISODES_FILE, SWEEP_FILE
    from pipelines.loop.interrupt import stop_status

    cfg, out = _checked_config(args)
    config = _sweep_config(args, cfg, out)
    if args.reuse is not None and args.report_only:
        raise PipelineError("--reuse takes episodes for a sweep that runs; --report-only runs nothing")
    if args.report_only:
        config = recorded_plan(cfg, config)  # the sweep that is there, not another plan
    experiment = config.experiment
    tasks = config.tasks()
    cells = experiment.cells(config.humans, config.n_robots)
    models = None  # the predictors the notes and the plan's checks read, read once for both
    folders = (out, args.reuse)  # named where one ran a value refused now (recorded.ran_beyond_bound_in)
    if not args.report_only:
        models = noted_models(experiment, cfg, cells)  # a killed calibrate's blocks taken out first
    if args.dry_run:
        check_plan(experiment, cfg, models, folders)  # a plan whose every episode would fail is not fine
        check_first_episodes(tasks)
        _quick_check_notes(cells, models)
        from pipelines.commands.sweep_dry_run import print_plan

        print_plan(config, cells, tasks, args.reuse, models)
        return 0

    status, workers = 0, None  # workers: those the run's backend started (None: no run)
    log: LogRead | None = None  # None: the report reads the log
    if not args.report_only:
        check_plan(experiment, cfg, models, folders)
        check_first_episodes(tasks)
        if config.jit:
            check_compile_cache(cfg.label("sweep", "jit"), cfg.sweep.jit)
        _quick_check_notes(cells, models)
        # what the report takes of the log, filled as the sweep reads its records and appends new ones: the
        # log is read once (and its planned lines once more, by offset, for episodes.csv), not scanned again
        log = LogRead.of_plan(cells, tasks)
        try:
            # the workers load the weights checked, and their blocks
            status, workers = run_cells(config, log, models)
        except SweepStopped as stopped:
            report_stopped(config, cells, tasks, log, stopped.workers)  # what it recorded stands
            raise
        if status == INTERRUPTED:  # a record appended as the interrupt came may not have reached ``log``
            log = None
    elif not (out / EPISODES_FILE).exists():
        raise PipelineError(_nothing_recorded(out))
    if args.report_only or (out / SWEEP_FILE).exists():  # none: stopped before it started, nothing to tell
        report(config, cells, tasks, report_only=args.report_only, log=log, workers=workers)
    return stop_status() if status == INTERRUPTED else status  # 143 for SIGTERM (pipelines.loop.interrupt)


def _quick_check_notes(cells: Iterable[Cell], models: PlanModels | None) -> None:
    """The quick-check models' notes, once the plan's checks took it: with the notes before them
    (``noted_models``) they preceded refusals they have nothing to do with (a plugin not registered)."""
    from pipelines.commands.quick_check_notes import method_quick_check_notes
    from pipelines.errors import print_note

    for note in method_quick_check_notes(cells, {} if models is None else models.entries):
        print_note(note)


def _nothing_recorded(out: Path) -> str:
    """Why --report-only has nothing to report in ``out``: no episode recorded, and whether some raised."""
    from pipelines.experiments.log import EPISODES_FILE, ERRORS_FILE

    if (out / ERRORS_FILE).is_file():
        return (
            f"{out} holds no recorded episode, only episodes that raised (see {out / ERRORS_FILE}): "
            "nothing to report; rerun the sweep without --report-only to retry them"
        )
    return f"{out / EPISODES_FILE} does not exist: nothing to report"


def _checked_config(args: argparse.Namespace) -> tuple[RunConfig, Path]:
    """The run's configuration and its --out, every number and name checked (pipelines/config) before
    anything is written or started."""
    from pipelines.config import command_config
    from pipelines.config.recorded import report_config
    from pipelines.experiments.log import SWEEP_FILE
    from pipelines.experiments.ray_join import check_output_outside_job_copy
    from pipelines.experiments.sweep_folder import check_sweep_directory

    # a report of the sweep in --out: its recorded config beneath what is typed
    options = config_options()
    cfg = report_config(args, options) if args.report_only else command_config(args, options)
    settings = cfg.sweep
    given = Path(settings.out or "")
    if given.name == SWEEP_FILE and given.is_file():  # as `config show --from-sweep` says it
        where = f"{cfg.label('sweep', 'out')} {given}"
        raise PipelineError(f"{where}: that is a sweep's file; give its folder, {given.parent}")
    # a report reads its experiment in --out's sweep.json: a folder without one is named before the option
    for key in ("out", "experiment") if args.report_only else ("experiment", "out"):
        if getattr(settings, key) is None:
            no_sweep = not (Path(settings.out or "") / SWEEP_FILE).is_file()
            if key == "experiment" and args.report_only and no_sweep:
                raise PipelineError(f"{settings.out} holds no sweep ({SWEEP_FILE}): nothing to report")
            args.parser_error(f"the following arguments are required: --{key} (or [sweep] {key})")
    out = without_missing_parents(Path(settings.out or ""))
    check_output_outside_job_copy(out, cfg.label("sweep", "out"))  # a `ray job submit` entrypoint's
    if not args.dry_run:
        check_writable(out, cfg.label("sweep", "out"), directory=True)
    check_sweep_directory(out, cfg.label("sweep", "out"))  # reads only: a dry run planned into others' files
    check_world(cfg)
    if not args.report_only:  # a report starts no worker
        check_mpc_solvable(cfg, (out, args.reuse))  # not of a report: a folder that ran beyond one reads back
        check_iterations_recorded(cfg)
        _check_this_machine(cfg)
    return cfg, out


def _check_this_machine(cfg: RunConfig) -> None:
    """The workers a local pool takes here: checked as the sweep is about to run them, not as the config is
    read (a config recorded by a bigger machine's sweep is read back on any machine)."""
    from pipelines.config import ConfigError

    problem = cfg.sweep.beyond_this_machine()
    source = cfg.source("sweep", "workers")
    if problem is not None:
        raise ConfigError(problem if source is None else source.label("sweep", "workers", problem))


def _sweep_config(args: argparse.Namespace, cfg: RunConfig, out: Path) -> SweepConfig:
    from pipelines.experiments.sweep_config import SweepConfig

    settings = cfg.sweep
    experiment = configured_experiment(cfg, run=not args.report_only)  # a report reads what ran
    return SweepConfig(
        experiment=experiment,
        out=out,
        episodes_per_cell=settings.episodes_per_cell,
        humans=settings.humans,
        seed=settings.seed,
        n_robots=cfg.scenario.robots,
        workers=settings.n_workers,
        backend=settings.backend,
        ray_address=settings.ray_address,
        record=settings.record,
        progress=False if args.no_progress else None,  # a bar on a terminal only: logs stay clean
        episode_timeout_s=settings.episode_timeout_s,
        # nothing to compile (baselines only), or nothing run (--report-only): gcc is not needed
        jit=not args.report_only
        and any(spec.kind.compiles for _, spec in experiment.methods)
        and choose_jit(
            settings.jit,
            cfg.label("sweep", "jit"),
            experiment,
            settings.humans,
            cfg.scenario.robots,
            settings.episodes_per_cell,
        ),
        run_config={"config_file": cfg.path, **cfg.effective()},
        reuse=args.reuse,
    )
