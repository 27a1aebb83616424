"""``crowdmpc sweep``: run an experiment's cells (Tables II/III, ablations) resumably, and tabulate them."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from pipelines.commands import check_writable, humans_list
from pipelines.errors import PipelineError

if TYPE_CHECKING:
    from pipelines.experiments.cells import Experiment

EPILOG = """examples:
  crowdmpc sweep --experiment table2 --episodes-per-cell 100 --workers 2 --out runs/table2
  crowdmpc sweep --experiment table2 --predictor constant_velocity --humans 7 --episodes-per-cell 4 \\
      --out /tmp/sw
  crowdmpc sweep --experiment predictors --episodes-per-cell 100 --record failures --out runs/predictors
  crowdmpc --plugin my_predictor:MyNet sweep --experiment predictors \\
      --predictors constant_velocity,social_lstm_eth,my_net_eth --episodes-per-cell 20 --out runs/swap
  crowdmpc sweep --experiment table2 --margins conformal:0.1 --profile paper --out runs/table2-cp
  crowdmpc sweep --experiment table3 --workers 64 --ray-address ray://head:10001 --out /shared/runs/table3

Experiments: table2 (CMPC vs DMPC), table3 (CMPC with/without flocking), both x 5-9 humans with the paper's
figures beside ours; predictors (CMPC at 7 humans with each predictor and an ORCA-ground-truth oracle; by
default the shipped models, --predictors for any list of registered and zoo names, a user zoo's included);
coupling (CMPC by iterated best response vs the coupled NLP, exact and first-order, 7 humans); safety
(CMPC without margins and with conformal margins at alpha 0.5 .. 0.01, 7 humans); conventions (simulation
profile x robot visibility x margins, 7 humans); baselines (straight and ORCA robots, a quick check).
--margins, --profile and --visibility apply to every method of table2, table3, predictors and coupling.
Episode i of every cell is the same crowd (circle for even i, perpendicular for odd i, seed --seed + i // 2).

Rerunning the same command resumes: episodes already in DIR/episodes.jsonl are not run again (a larger
--episodes-per-cell extends the sweep). Outputs in DIR: episodes.jsonl, errors.jsonl (episodes that raised;
retried on rerun), cells.csv, episodes.csv, table.md, success_vs_humans.png, travel_time_vs_humans.png,
sweep.json, and with --record the MCAP logs in DIR/mcap/<cell>/.
"""


# A local pool (processes, or a local Ray) gets at most this many workers per CPU: more only queue for the
# same cores, each holding its own solvers and predictor in memory. A Ray cluster (--ray-address) takes more.
LOCAL_WORKERS_PER_CPU = 4


def _cpus() -> int:
    """CPUs this process may use (a container or taskset may allow fewer than the machine has)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def register(subparsers: argparse._SubParsersAction) -> None:
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
    p.add_argument("--experiment", required=True, choices=sorted(EXPERIMENTS))
    p.add_argument(
        "--episodes-per-cell",
        type=int,
        default=PAPER_EPISODES_PER_CELL,
        metavar="N",
        help=f"episodes per cell, half of each scenario (default {PAPER_EPISODES_PER_CELL}, the paper's)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=_cpus(),
        metavar="K",
        help="parallel workers (default: the CPUs this process may use)",
    )
    p.add_argument(
        "--ray-address", metavar="ADDR", help="run on this Ray cluster (needs the [cluster] extra)"
    )
    p.add_argument(
        "--backend",
        choices=BACKENDS,
        default="auto",
        help="auto (default): Ray when installed, else a local process pool; inline: in this process",
    )
    p.add_argument(
        "--humans", type=humans_list, metavar="5,6,7", help="numbers of humans (default: the experiment's)"
    )
    p.add_argument("--robots", type=int, default=3, help="robots per episode (default 3)")
    p.add_argument("--seed", type=int, default=0, help="base scenario seed (default 0)")
    _add_method_options(p)
    _add_execution_options(p)
    p.set_defaults(func=run)


# A swap table of more predictors than this is no table anyone reads; each is a column of every row.
MAX_SWAP_PREDICTORS = 64


def predictor_list(text: str) -> tuple[str, ...]:
    """An argparse type: ``a,b,c`` -> ("a", "b", "c"), each a well-formed predictor name."""
    from predictors.zoo import NAME_PATTERN

    names = tuple(name.strip() for name in text.split(",") if name.strip())
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
        "--margins",
        metavar="SPEC",
        help="safety margins of every method: none (the paper), conformal[:ALPHA[:closed-loop|real]], "
        "fixed:M1,..,MH (default: the experiment's own, none for table2/table3/predictors/coupling)",
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


def _add_execution_options(p: argparse.ArgumentParser) -> None:
    """Where the sweep goes, what it keeps, and how it runs."""
    from pipelines.experiments.worker import RECORD_POLICIES

    p.add_argument(
        "--record",
        choices=RECORD_POLICIES,
        default="none",
        help="keep MCAP logs: of failed episodes (not all robots arrived, or a collision), all, or none",
    )
    p.add_argument(
        "--out", type=Path, required=True, metavar="DIR", help="sweep directory (created; resumed)"
    )
    p.add_argument(
        "--report-only", action="store_true", help="write the table and plots from DIR; run nothing"
    )
    p.add_argument("--dry-run", action="store_true", help="print the cells and episode count; run nothing")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--jit",
        choices=("auto", "on", "off"),
        default="auto",
        help="compile the MPC NLPs with gcc in every worker: 2-8 s a build, then solves ~2x faster "
        "(auto, the default: on when gcc is found)",
    )


def _jit(choice: str) -> bool:
    from pipelines.experiments.worker import jit_available

    if choice == "on" and not jit_available():
        raise PipelineError("--jit on needs gcc on the PATH (CasADi compiles with it); use --jit off")
    return choice == "on" or (choice == "auto" and jit_available())


def _check_predictors(experiment: Experiment) -> None:
    """Fail before starting workers, not once per episode in errors.jsonl: every predictor is registered or
    in a zoo, and a zoo model's kind is registered (a plugin's, with --plugin, which the workers inherit)."""
    from predictors import zoo
    from predictors.errors import PredictorError
    from predictors.models import model_kind
    from predictors.registry import available

    known = set(available())
    wanted = {spec.predictor for _, spec in experiment.methods}
    missing = sorted(wanted - known)
    if missing:
        hint = "--predictors" if experiment.predictor_list else "--predictor"
        raise PipelineError(
            f"experiment {experiment.name!r} needs predictors {missing} that are not available; "
            f"available: {sorted(known)} (train or fetch the zoo models, or pass {hint})"
        )
    for name in sorted(wanted):
        located = zoo.locate(name)
        if located is not None:
            try:
                model_kind(located.entry.model)
            except PredictorError as exc:
                raise PipelineError(f"predictor {name!r} of the {located.source} zoo: {exc}") from None


def _check_margins(experiment: Experiment) -> None:
    """Every method's margins resolve (a calibration that matches the weights) before workers start."""
    from pipelines.loop.mpc import mpc_config
    from predictors.registry import checkpoint_sha256

    for _, spec in experiment.methods:
        name = spec.predictor_name
        spec.margins.resolve(name, mpc_config(spec).horizon, checkpoint_sha256(name))


def configured_experiment(args: argparse.Namespace) -> Experiment:
    """The experiment with the command line's --predictors, --predictor, --margins, --profile and
    --visibility applied."""
    from pipelines.experiments.cells import World, get_experiment
    from pipelines.loop.margins import parse_margins

    experiment = get_experiment(args.experiment)
    if args.predictors is not None:
        experiment = experiment.with_predictors(args.predictors)
    elif experiment.predictor_list:
        from pipelines.experiments.cells import swap_predictors
        from predictors.registry import available

        experiment = experiment.with_predictors(swap_predictors(available()))
    if args.predictor:
        experiment = experiment.with_predictor(args.predictor)
    if args.margins:
        experiment = experiment.with_margins(parse_margins(args.margins))
    if args.profile or args.visibility:
        world = World(
            args.profile or experiment.world.profile, args.visibility or experiment.world.visibility
        )
        experiment = experiment.with_world(world)
    return experiment


def _check_workers(args: argparse.Namespace) -> None:
    """Local workers within what this machine can run (the bounds of every sweep are SweepConfig's)."""
    if args.ray_address is not None or args.backend == "inline" or args.workers < 1:
        return
    most = max(LOCAL_WORKERS_PER_CPU * _cpus(), 8)
    if args.workers > most:
        raise PipelineError(
            f"--workers {args.workers}: at most {most} here ({LOCAL_WORKERS_PER_CPU} per CPU this process "
            f"may use, {_cpus()}); more only queue for the same cores (a Ray cluster takes more)"
        )


def run(args: argparse.Namespace) -> int:
    from pipelines.experiments.log import EPISODES_FILE, episode_log
    from pipelines.experiments.report import write_report
    from pipelines.experiments.sweep import SweepConfig, run_sweep

    _check_workers(args)
    if not args.dry_run:
        check_writable(args.out, "--out", directory=True)
    experiment = configured_experiment(args)
    config = SweepConfig(
        experiment=experiment,
        out=args.out,
        episodes_per_cell=args.episodes_per_cell,
        humans=args.humans,
        seed=args.seed,
        n_robots=args.robots,
        workers=args.workers,
        backend=args.backend,
        ray_address=args.ray_address,
        record=args.record,
        progress=not args.no_progress,
        # nothing to compile (baselines only): gcc is not needed, workers stay where they are
        jit=any(spec.kind.compiles for _, spec in experiment.methods) and _jit(args.jit),
    )
    tasks = config.tasks()
    cells = experiment.cells(config.humans, config.n_robots)
    if args.dry_run:
        print(f"{experiment.title}: {len(cells)} cells x {config.episodes_per_cell} episodes = {len(tasks)}")
        for cell in cells:
            print(f"  {cell.method:>22}  {cell.n_humans} humans  {cell.key}")
        return 0

    status = 0
    if not args.report_only:
        _check_predictors(experiment)
        _check_margins(experiment)
        outcome = run_sweep(config)
        done = outcome.already_done + outcome.ran
        rate = (
            f", {outcome.episodes_per_minute:.1f} episodes/min; "
            f"{outcome.steady_episodes_per_minute:.1f} after {outcome.startup_s:.1f} s of worker start-up"
            if outcome.ran
            else ""
        )
        print(
            f"{experiment.name}: {done}/{outcome.planned} episodes recorded ({outcome.ran} this run in "
            f"{outcome.wall_s:.0f} s{rate}, backend {outcome.backend or '-'})",
            file=sys.stderr,
        )
        if outcome.errors:
            print(
                f"{len(outcome.errors)} episodes raised; see {args.out / 'errors.jsonl'} (a rerun retries)",
                file=sys.stderr,
            )
            status = 1
        if outcome.interrupted:
            print("interrupted: rerun the same command to resume", file=sys.stderr)
            status = 130
    elif not (args.out / EPISODES_FILE).exists():
        raise PipelineError(f"{args.out / EPISODES_FILE} does not exist: nothing to report")

    planned = {t.key for t in tasks}
    records = [r for key, r in episode_log(args.out).load(repair=False).items() if key in planned]
    report = write_report(args.out, experiment, cells, records)
    print(report.markdown)
    print("wrote " + ", ".join(str(p) for p in report.files), file=sys.stderr)
    cpu = [r["cpu_s"] for r in records if r.get("cpu_s") is not None]
    if cpu:
        # CPU time, unlike wall time, does not depend on what else runs on the machine: an honest projection.
        mean = sum(cpu) / len(cpu)
        hours = mean * len(tasks) / 3600
        k = config.workers
        print(
            f"CPU per episode {mean:.2f} s (mean of {len(cpu)}); the {len(tasks)} planned episodes take "
            f"{hours:.2f} CPU-hours: {hours / k:.2f} h for {k} workers on {k} free cores",
            file=sys.stderr,
        )
    return status
