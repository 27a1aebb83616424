"""``crowdmpc simulate``: closed-loop episodes of one controller in one scenario, with a metrics table."""

from __future__ import annotations

import argparse
import sys
import warnings
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from crowdsim.profiles import PROFILES, VISIBILITY
from crowdsim.replay import CROWDS
from crowdsim.scenarios import MAX_HUMANS, MAX_ROBOTS, SCENARIOS
from pipelines.commands import check_writable
from pipelines.commands.calibrate_store import take_back_before_planning
from pipelines.commands.output_paths import without_missing_parents
from pipelines.commands.simulate_help import EPILOG, coupling_help, margins_help
from pipelines.commands.simulate_json import write_json
from pipelines.commands.simulate_table import format_table, plot_first_episode, table_header
from pipelines.commands.standard_output import is_stdout, json_on_stdout, json_path
from pipelines.errors import CloseFailed, PipelineError, RecordingRefused, quiet_team_warnings
from pipelines.loop.controllers import COUPLINGS, ControllerSpec, controller_name
from pipelines.loop.replay_data import CROWD_HELP

if TYPE_CHECKING:
    from pipelines.commands.simulate_reads import PredictorRead
    from pipelines.config import Option, RunConfig
    from pipelines.loop.episode import EpisodeResult


# The options that set a config key when given (their defaults are the config's: pipelines/config).
def _options() -> tuple[Option, ...]:
    from pipelines.config import Option

    return (
        Option("controller", "controller", "controller", "--controller"),
        Option("predictor", "controller", "predictor", "--predictor"),
        Option("no_flocking", "controller", "flocking", "--no-flocking", lambda v: not v),
        Option("coupling", "controller", "coupling", "--coupling"),
        Option("margins", "controller", "margins", "--margins"),
        Option("record_iterations", "controller", "record_iterations", "--record-iterations"),
        Option("profile", "env", "profile", "--profile"),
        Option("visibility", "env", "robots_visible", "--visibility", lambda v: v == "visible"),
        Option("crowd", "env", "crowd", "--crowd"),
        Option("scenario", "scenario", "name", "--scenario"),
        Option("humans", "scenario", "humans", "--humans"),
        Option("robots", "scenario", "robots", "--robots"),
        Option("episodes", "simulate", "episodes", "--episodes"),
        Option("seed", "simulate", "seed", "--seed"),
        Option("json", "simulate", "json", "--json"),
        Option("plot", "simulate", "plot", "--plot"),
        Option("record", "simulate", "record", "--record"),
        Option("no_progress", "simulate", "progress", "--no-progress", lambda v: not v),
        Option("sensor_range", "simulate", "sensor_range", "--sensor-range"),
        Option("no_sensor_tracks", "simulate", "sensor_tracks", "--no-sensor-tracks", lambda v: not v),
    )


def register(subparsers: argparse._SubParsersAction) -> None:
    from pipelines.commands.config import add_config_options

    parser = subparsers.add_parser(
        "simulate",
        help="run closed-loop episodes and print the paper's metrics",
        description="Run a robot controller in the ORCA crowd simulator and report success, travel time, "
        "collision, contact and discomfort rates and the cost of each control step.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    # Defaults are None: an option given overrides the config (file, --set), whose defaults are these.
    _add_run_options(parser)
    _add_output_options(parser)
    _add_sensing_options(parser)
    parser.add_argument(
        "--no-progress", action="store_true", default=None, help="no progress bar (drawn on a terminal only)"
    )
    add_config_options(parser)
    parser.set_defaults(func=run, parser_error=parser.error)


def _add_run_options(parser: argparse.ArgumentParser) -> None:
    """What runs: the controller, the scenario, its team and its crowd, the episodes."""
    from pipelines.config.schema import key_default

    parser.add_argument(
        "--controller",
        type=controller_name,
        metavar="NAME",
        help="robot controller: straight, orca, cmpc, dmpc or a registered plugin's name (required, here or "
        "as [controller] controller in --config)",
    )
    parser.add_argument(
        "--predictor",
        help="predictor of cmpc/dmpc: a registered name or a model of the shipped or user zoo "
        f"(default: {ControllerSpec.predictor})",  # what an unset one runs (run): the schema has none
    )
    # the config's defaults, read from its schema: literals here could drift from them
    scenario, simulate = partial(key_default, "scenario"), partial(key_default, "simulate")
    controller, env = partial(key_default, "controller"), partial(key_default, "env")
    where = f"where the humans start and head (default: {scenario('name')})"
    parser.add_argument("--scenario", choices=sorted(SCENARIOS), help=where)
    parser.add_argument(
        "--humans", type=int, help=f"humans per episode, 0..{MAX_HUMANS} (default: {scenario('humans')})"
    )
    parser.add_argument(
        "--robots", type=int, help=f"robots per episode, 1..{MAX_ROBOTS} (default: {scenario('robots')})"
    )
    parser.add_argument("--episodes", type=int, help=f"episodes to run (default: {simulate('episodes')})")
    parser.add_argument("--seed", type=int, help=f"first episode's seed (default: {simulate('seed')})")
    no_floc = "plan without the flocking cost: omega_floc = 0 (Table III, NF)"
    parser.add_argument("--no-flocking", action="store_true", default=None, help=no_floc)
    parser.add_argument("--coupling", choices=COUPLINGS, help=coupling_help(controller("coupling")))
    # what unset margins plan with (run): the schema has none, a sweep's experiment its own
    parser.add_argument("--margins", metavar="SPEC", help=margins_help(ControllerSpec.margins.mode))
    conventions = f"simulation conventions (default: {env('profile')})"
    parser.add_argument("--profile", choices=sorted(PROFILES), help=conventions)
    visible = VISIBILITY[0] if env("robots_visible") else VISIBILITY[1]
    parser.add_argument(
        "--visibility", choices=VISIBILITY, help=f"robots seen by the humans' ORCA (default: {visible})"
    )
    parser.add_argument("--crowd", choices=CROWDS, help=CROWD_HELP)


def _add_output_options(parser: argparse.ArgumentParser) -> None:
    """The files a run writes: its report, the first episode's plot, the recordings."""
    parser.add_argument(
        "--json",
        metavar="FILE",
        help="write the summary and per-episode records (-: standard output; fields: docs/outputs.md)",
    )
    parser.add_argument("--plot", metavar="FILE", help="draw the first episode (PNG, PDF, SVG)")
    parser.add_argument("--record", metavar="DIR", help="record each episode as an MCAP file in DIR")
    parser.add_argument(
        "--record-iterations",
        action="store_true",
        default=None,
        help="record every IBR iteration's prediction in the --record files (cmpc, dmpc)",
    )


def _add_sensing_options(parser: argparse.ArgumentParser) -> None:
    """What the controller sees of the crowd."""
    parser.add_argument(
        "--sensor-range",
        type=float,
        metavar="M",
        help="the controller sees only the humans within M metres of some robot, each from when it came into "
        "view, as a tracker gives them (docs/extending.md, section 7; default: every human)",
    )
    parser.add_argument(
        "--no-sensor-tracks",
        action="store_true",
        default=None,
        help="with --sensor-range: the tracker reports no track lengths (a late arrival's padded past reads "
        "as its own)",
    )


@dataclass(frozen=True)
class SimulateRun:
    """What one ``simulate`` runs, resolved from the defaults, the config file, ``--set`` and the options."""

    config: RunConfig
    spec: ControllerSpec
    json: Path | None
    plot: Path | None
    record: Path | None
    read: PredictorRead | None = None  # the predictor as its checks read it (None: none read yet)

    @property
    def controller(self) -> str:
        return self.spec.controller


def resolve_run(args: argparse.Namespace) -> SimulateRun:
    """The run's effective config, with every number and output path checked before any work starts."""
    from pipelines.commands.simulate_checks import check_choices_apply, check_file_outputs
    from pipelines.config import command_config
    from pipelines.loop.margins import parse_margins

    config = command_config(args, _options())
    chosen = config.controller
    if chosen.controller is None:  # the parser's own one-line error, as for any missing option
        args.parser_error("the following arguments are required: --controller (or [controller] controller)")
        raise SystemExit(2)  # parser_error exits
    spec = ControllerSpec(
        controller=chosen.controller,
        predictor=chosen.predictor or ControllerSpec.predictor,
        flocking=chosen.flocking,
        coupling=chosen.coupling,  # type: ignore[arg-type]  # one of COUPLINGS (settings check it)
        record_iterations=chosen.record_iterations,
        mpc_overrides=config.mpc_overrides(),
        margins=parse_margins(chosen.margins) if chosen.margins else ControllerSpec.margins,
    )
    read = check_choices_apply(config, spec)
    check_file_outputs(config)
    paths = {name: getattr(config.simulate, name) for name in ("plot", "record")}
    json_out = None if config.simulate.json is None else json_path(config.simulate.json)
    outputs = {k: None if v is None else without_missing_parents(Path(v)) for k, v in paths.items()}
    run = SimulateRun(config, spec, json_out, **outputs, read=read)
    if run.plot is not None:
        from crowdsim.plotting import check_figure_path

        check_figure_path(run.plot, config.label("simulate", "plot"))
    # Before the episodes, not after them: a path that cannot be written would waste the whole run.
    inputs = [] if config.path is None else [Path(config.path)]  # an empty config file took a report
    check_writable(run.json, config.label("simulate", "json"), json_only=True, inputs=inputs)
    check_writable(run.plot, config.label("simulate", "plot"), room=0, inputs=inputs)  # save_figure: no room
    check_writable(run.record, config.label("simulate", "record"), directory=True)
    json_file = None if is_stdout(run.json) else run.json
    if json_file is not None and run.plot is not None and json_file.resolve() == run.plot.resolve():
        # the plot, written last, replaced the JSON report
        raise PipelineError(
            f"{config.label('simulate', 'json')} and {config.label('simulate', 'plot')} name the same file "
            f"{run.json}; give each its own"
        )
    for name, out in (("json", json_file), ("plot", run.plot)):
        if out is not None and run.record is not None and out.resolve() == run.record.resolve():
            # the recorder makes the folder first, and the file could not be written after every episode
            raise PipelineError(
                f"{config.label('simulate', name)} {out} is {config.label('simulate', 'record')}'s folder; "
                "give it another path (a file in the folder is fine)"
            )
    return run


def _run_meta(run: SimulateRun) -> dict[str, Any]:
    """The run's choices, for the JSON output and every MCAP file's "run" metadata: the main ones at the top,
    and the whole effective config (with the config file it came from) under "config"."""
    from pipelines.loop.replay_data import crowd_sha256

    cfg, spec = run.config, run.spec
    return {
        "command": "simulate",
        "argv": sys.argv[1:],
        "controller": spec.controller,
        "predictor": spec.predictor_name,
        "flocking": spec.flocking,
        "coupling": spec.coupling,
        "margins": spec.margins.label,
        "profile": cfg.env.profile,
        "visibility": "visible" if cfg.env.robots_visible else "invisible",
        "goals": cfg.env.goal_assignment,
        "formation": cfg.env.formation,
        "crowd": cfg.env.crowd,
        "crowd_sha256": crowd_sha256(cfg.env.crowd),  # as a sweep's records: compare pairs files by it
        "scenario": cfg.scenario.name,
        "humans": cfg.scenario.humans,
        "robots": cfg.scenario.robots,
        "episodes": cfg.simulate.episodes,
        "seed": cfg.simulate.seed,
        "config_file": cfg.path,
        "config": cfg.effective(),
    }


def run(args: argparse.Namespace) -> int:
    resolved = resolve_run(args)
    take_back_before_planning([resolved.spec.margins])  # a calibrate killed mid-run left blocks it stored
    with json_on_stdout(resolved.json):  # --json -: the JSON alone on stdout, the rest on stderr
        return _simulate(resolved)


def _simulate(resolved: SimulateRun) -> int:
    from pipelines.commands.simulate_notes import noted_reads
    from pipelines.loop.episode import run_episodes

    cfg, spec = resolved.config, resolved.spec
    scenario, sim = cfg.scenario, cfg.simulate
    read = noted_reads(cfg, spec, resolved.read)
    env_config = cfg.env
    run_meta = _run_meta(resolved)
    recorder = None
    if resolved.record is not None:
        from pipelines.logs.recording import McapEpisodeRecorder

        recorder = McapEpisodeRecorder(
            resolved.record,
            record_iterations=spec.record_iterations,
            run_meta=run_meta,
            seeds=range(sim.seed, sim.seed + sim.episodes),
        )
    from pipelines.loop.record import EpisodeConfigs

    configs = EpisodeConfigs()
    observers = (configs,) if recorder is None else (recorder, configs)
    results = _FirstWhole()
    interrupted = False
    failure: PipelineError | None = None
    try:
        with warnings.catch_warnings():
            quiet_team_warnings()  # the controller's notes on the layout: said above, in the CLI's words
            run_episodes(
                spec,
                episodes=sim.episodes,
                seed=sim.seed,
                scenario=scenario.name,
                n_humans=scenario.humans,
                n_robots=scenario.robots,
                observers_factory=lambda: observers,
                progress=None if sim.progress else False,  # a bar on a terminal only: logs stay clean
                env_config=env_config,
                into=results,
                sensor_range=sim.sensor_range,
                sensor_tracks=sim.sensor_tracks,
                read=read,
            )
    except KeyboardInterrupt:
        if not results:
            if recorder is not None and recorder.paths:  # no report follows: the cut file would go unsaid
                print(recorder.written_line(finished=0))
            write_json(resolved.json, run_meta, [], configs.configs, True, None)
            raise
        interrupted = True  # the finished episodes are reported and written, then the interrupt goes on
    except PipelineError as exc:  # a plugin's, in an episode (EpisodeFailed) or in close() after the last
        if not results:
            if not isinstance(exc.__cause__, RecordingRefused):  # a refusal of --record writes nothing
                write_json(resolved.json, run_meta, [], configs.configs, False, exc)
            raise
        failure = exc  # as an interrupt: the finished episodes are reported, then the error's line
    finally:
        if recorder is not None:
            recorder.close()
    _report(resolved, run_meta, results, configs.configs, recorder, interrupted, failure)
    if interrupted:
        raise KeyboardInterrupt
    if failure is not None:
        raise failure
    return 0


def _report(
    resolved: SimulateRun,
    run_meta: dict[str, Any],
    results: list[EpisodeResult],
    configs: list[dict[str, Any]],
    recorder: Any,
    interrupted: bool,
    failure: PipelineError | None = None,
) -> None:
    """The summary table, --json, --plot and the recordings' line of the episodes that ran (when
    ``interrupted`` or stopped by ``failure``, those that finished, said so in the header and the JSON).
    ``configs``: each episode's effective config, in the order they started (EpisodeConfigs)."""
    from pipelines.loop.episode import summarize

    cfg, spec = resolved.config, resolved.spec
    env_config = cfg.env
    summary = summarize(results)
    stopped_early = failure is not None and not isinstance(failure, CloseFailed)  # not after the last
    finished = len(results) if interrupted or stopped_early else None
    stopped = "interrupted" if interrupted else "stopped by an error"
    header = table_header(cfg, spec, run_meta, finished, stopped, configs[0] if configs else None)
    print(format_table(summary, header, env_config.radius, cfg.mpc.time_limit_s))
    write_json(resolved.json, run_meta, results, configs, interrupted, failure, summary)
    if resolved.plot is not None:
        plot_first_episode(resolved.plot, spec.controller, results[0], env_config, cfg.simulate.sensor_range)
    if recorder is not None:
        print(recorder.written_line(finished=len(results)))


class _FirstWhole(list["EpisodeResult"]):
    """simulate's results: the first episode whole (--plot draws it), each later one without its
    trajectories, which the summary and --json do not read: held whole, they grew a 10,000-episode run by
    about 400 MB."""

    def append(self, result: EpisodeResult) -> None:
        if self:
            import dataclasses

            import numpy as np

            shape = (0, *result.robot_positions.shape[1:]), (0, *result.human_positions.shape[1:])
            result = dataclasses.replace(
                result,
                robot_positions=np.empty(shape[0]),
                human_positions=np.empty(shape[1]),
                human_present=None,
            )
        super().append(result)
