"""``crowdmpc sweep``: run an experiment's cells (Tables II/III, ablations) resumably, and tabulate them."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from pipelines.commands import check_writable, comma_items, humans_list, path_arg
from pipelines.commands.output_paths import without_missing_parents
from pipelines.commands.simulate_checks import check_mpc_solvable
from pipelines.commands.sweep_checks import check_plan, noted_models
from pipelines.commands.sweep_first_episodes import check_first_episodes
from pipelines.commands.sweep_help import EPILOG
from pipelines.commands.sweep_jit import check_compile_cache, choose_jit
from pipelines.commands.sweep_plan import check_iterations_recorded, check_world, configured_experiment
from pipelines.errors import PipelineError, SweepStopped

if TYPE_CHECKING:
    from pipelines.commands.sweep_report import LogRead
    from pipelines.config import Option, RunConfig
    from pipelines.experiments.sweep_config import SweepConfig


# The options that set a config key when given (their defaults are the config's: pipelines/config).
def _options() -> tuple[Option, ...]:
    from pipelines.config import Option

    return (
        Option("experiment", "sweep", "experiment", "--experiment"),
        Option("out", "sweep", "out", "--out"),
        Option("episodes_per_cell", "sweep", "episodes_per_cell", "--episodes-per-cell"),
        Option("humans", "sweep", "humans", "--humans"),
        Option("seed", "sweep", "seed", "--seed"),
        Option("workers", "sweep", "workers", "--workers"),
        Option("backend", "sweep", "backend", "--backend"),
        Option("ray_address", "sweep", "ray_address", "--ray-address"),
        Option("record", "sweep", "record", "--record"),
        Option("jit", "sweep", "jit", "--jit"),
        Option("episode_timeout", "sweep", "episode_timeout_s", "--episode-timeout"),
        Option("predictors", "sweep", "predictors", "--predictors"),
        Option("controllers", "sweep", "controllers", "--controllers"),
        Option("robots", "scenario", "robots", "--robots"),
        Option("predictor", "controller", "predictor", "--predictor"),
        Option("margins", "controller", "margins", "--margins"),
        Option("profile", "env", "profile", "--profile"),
        Option("visibility", "env", "robots_visible", "--visibility", lambda v: v == "visible"),
        Option("crowd", "env", "crowd", "--crowd"),
        Option("sensor_range", "simulate", "sensor_range", "--sensor-range"),
        Option("no_sensor_tracks", "simulate", "sensor_tracks", "--no-sensor-tracks", lambda v: not v),
        Option("vary", "sweep", "vary", "--vary", ";".join),
    )


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
        help=f"episodes per cell, half of each scenario (default {PAPER_EPISODES_PER_CELL}, the paper's)",
    )
    p.add_argument(
        "--workers", type=int, metavar="K", help="parallel workers (default: the CPUs this process may use)"
    )
    p.add_argument(
        "--ray-address",
        metavar="ADDR",
        help="run on this Ray cluster: the address `ray start --head` printed (HOST:6379) or "
        "ray://HOST:10001 (needs the [cluster] extra); --workers actors, at most one per free CPU there",
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
    _add_method_options(p)
    _add_execution_options(p)
    add_config_options(p)
    p.set_defaults(func=run, parser_error=p.error)


def controller_list(text: str) -> tuple[str, ...]:
    """An argparse type: ``a,b,c`` -> ("a", "b", "c"); whether each is registered is checked with the
    experiment (``Experiment.with_controllers``)."""
    from pipelines.config.settings import MAX_SWAP_PREDICTORS

    names = tuple(comma_items(text))
    if not names or len(names) > MAX_SWAP_PREDICTORS:
        raise argparse.ArgumentTypeError(
            f"expected 1 to {MAX_SWAP_PREDICTORS} names like cmpc,orca, got {text[:64]!r}"
        )
    return names


def predictor_list(text: str) -> tuple[str, ...]:
    """An argparse type: ``a,b,c`` -> ("a", "b", "c"), each a well-formed predictor name."""
    from pipelines.config.settings import MAX_SWAP_PREDICTORS
    from predictors.checkpoint import NAME_PATTERN

    names = tuple(comma_items(text))
    if not names:
        raise argparse.ArgumentTypeError(
            f"expected names like constant_velocity,social_lstm_eth, got {text!r}"
        )
    if len(names) > MAX_SWAP_PREDICTORS:
        raise argparse.ArgumentTypeError(f"at most {MAX_SWAP_PREDICTORS} names, got {len(names)}")
    bad = [name for name in names if NAME_PATTERN.fullmatch(name) is None]
    if bad:
        raise argparse.ArgumentTypeError(f"{bad[0][:64]!r} is not a predictor name")
    return names


def _add_method_options(p: argparse.ArgumentParser) -> None:
    """What replaces the experiment's own choices for every method."""
    from crowdsim.profiles import PROFILES, VISIBILITY
    from crowdsim.replay import CROWDS
    from pipelines.experiments.methods import SHIPPED_CONTROLLERS
    from pipelines.loop.replay_data import CROWD_HELP

    p.add_argument(
        "--predictor",
        metavar="NAME",
        help="replace the predictor of every method (table2/table3 default to social_lstm_eth, as the paper)",
    )
    p.add_argument(
        "--predictors",
        type=predictor_list,
        metavar="A,B,C",
        help="the predictors experiment's list, one column each (default: the shipped swap table, with "
        "social_gru_eth and social_attention_eth when the zoo has them)",
    )
    p.add_argument(
        "--controllers",
        type=controller_list,
        metavar="A,B,C",
        help="the controllers experiment's list, one column each (default: "
        f"{','.join(SHIPPED_CONTROLLERS)}; a plugin's module:Class after `crowdmpc --plugin module:Class`)",
    )
    p.add_argument(
        "--margins",
        metavar="SPEC",
        help="safety margins of every method: none (the paper), conformal[:ALPHA[:closed-loop|real]], "
        "conformal-motion[:ALPHA], conformal-shortfall[:ALPHA], fixed:M1,..,MH (default: the experiment's "
        "own, none for table2/table3/predictors/coupling)",
    )
    p.add_argument(
        "--profile",
        choices=sorted(PROFILES),
        help="simulation conventions (default paper: the authors' CrowdNav fork; v1: this project's first)",
    )
    p.add_argument(
        "--visibility",
        choices=VISIBILITY,
        help="whether the humans' ORCA sees the robots (default visible, as the authors' fork)",
    )
    p.add_argument("--crowd", choices=CROWDS, help=CROWD_HELP)
    p.add_argument(
        "--vary",
        action="append",
        metavar="mpc.KEY=V1,V2",
        help="a column per value of an [mpc] setting (or controller.margins=M1,M2) beside each method that "
        "plans, on the same crowds, or of scenario.robots=M1,M2, a simulator setting (env.KEY=V1,V2, "
        "env.orca.KEY=V1,V2; not the profile, visibility or crowd, which --profile, --visibility and --crowd "
        "set for the whole sweep) or simulate.sensor_range=R1,R2 beside every method (Table I's value is a "
        "plain sweep's cell); again: every combination",
    )
    p.add_argument(
        "--sensor-range",
        type=float,
        metavar="M",
        help="every method's controller sees only the humans within M metres of some robot, as a tracker "
        "gives them ([simulate] sensor_range; default: every human; the sensing experiment compares ranges)",
    )
    p.add_argument(
        "--no-sensor-tracks",
        action="store_true",
        default=None,
        help="with --sensor-range: the tracker reports no track lengths",
    )


def _add_execution_options(p: argparse.ArgumentParser) -> None:
    """Where the sweep goes, what it keeps, and how it runs."""
    from pipelines.config.settings import JIT_CHOICES
    from pipelines.experiments.worker import RECORD_POLICIES

    p.add_argument(
        "--record",
        choices=RECORD_POLICIES,
        help="keep MCAP logs: of failed episodes (not all robots arrived, or a collision), all, or none",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        help="sweep directory, created; resumed (required, here or in --config)",
    )
    p.add_argument(
        "--report-only",
        action="store_true",
        help="write the table and plots from DIR; run nothing (without --config, every setting not typed "
        "is the one DIR's last run recorded, --experiment too)",
    )
    p.add_argument(
        "--reuse",
        type=path_arg,
        metavar="OTHER",
        help="take the episodes sweep OTHER ran of this plan's cells first, with their runs' code (Table "
        "III's F cells are Table II's CMPC cells), then run the rest",
    )
    p.add_argument("--dry-run", action="store_true", help="print the cells and episode count; run nothing")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (drawn on a terminal only)")
    p.add_argument(
        "--episode-timeout",
        type=float,
        metavar="S",
        help="stop an episode after S s of wall-clock time (a controller that hangs), record it in "
        "errors.jsonl and go on ([sweep] episode_timeout_s; default: no limit)",
    )
    p.add_argument(
        "--jit",
        choices=JIT_CHOICES,
        help="compile the MPC NLPs with gcc, once per machine ($CROWDMPC_CACHE/compiled, `crowdmpc cache "
        "info`): 2-8 s a first compile; solves ~2x faster, ~0.1 s CPU saved a CMPC episode, ~0.2 s a DMPC "
        "one. auto (the default): on when gcc is found, the cache's disk has 64 MB free and the episodes "
        "repay compiling each NLP (8 s CPU joint, 2.3 s local, per distinct cell settings; from 12 episodes "
        "a cell for the 7-predictor swap, 36 for table2); a warm cache is not consulted",
    )


def run(args: argparse.Namespace) -> int:
    from pipelines.commands.sweep_report import (
        INTERRUPTED,
        LogRead,
        recorded_plan,
        report,
        report_stopped,
        run_cells,
    )
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
    if not args.report_only:
        models = noted_models(experiment, cfg, cells)  # a killed calibrate's blocks taken out first
    if args.dry_run:
        check_plan(experiment, cfg, models)  # a plan whose every episode would fail is not fine
        check_first_episodes(tasks)
        from pipelines.commands.sweep_dry_run import print_plan

        print_plan(config, cells, tasks, args.reuse)
        return 0

    status = 0
    log: LogRead | None = None  # None: the report reads the log
    if not args.report_only:
        check_plan(experiment, cfg, models)
        check_first_episodes(tasks)
        if config.jit:
            check_compile_cache(cfg.label("sweep", "jit"), cfg.sweep.jit)
        # what the report takes of the log, filled as the sweep reads its records and appends new ones: the
        # log is read once (and its planned lines once more, by offset, for episodes.csv), not scanned again
        log = LogRead.of_plan(cells, tasks)
        try:
            status = run_cells(config, log)
        except SweepStopped:
            report_stopped(config, cells, tasks, log)  # what it recorded stands
            raise
        if status == INTERRUPTED:  # a record appended as the interrupt came may not have reached ``log``
            log = None
    elif not (out / EPISODES_FILE).exists():
        raise PipelineError(_nothing_recorded(out))
    if args.report_only or (out / SWEEP_FILE).exists():  # none: stopped before it started, nothing to tell
        report(config, cells, tasks, report_only=args.report_only, log=log)
    return stop_status() if status == INTERRUPTED else status  # 143 for SIGTERM (pipelines.loop.interrupt)


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
    from pipelines.experiments.log import SWEEP_FILE, check_sweep_directory

    # a report of the sweep in --out: its recorded config beneath what is typed
    cfg = report_config(args, _options()) if args.report_only else command_config(args, _options())
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
