"""``crowdmpc simulate``: closed-loop episodes of one controller in one scenario, with a metrics table."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from crowdsim.profiles import PROFILES, VISIBILITY
from crowdsim.scenarios import MAX_HUMANS, MAX_ROBOTS, SCENARIOS
from pipelines.commands import check_writable
from pipelines.errors import PipelineError
from pipelines.loop.controllers import CONTROLLERS, COUPLINGS
from pipelines.plain_json import plain

if TYPE_CHECKING:
    from crowdsim.env import EnvConfig
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.episode import EpisodeResult

EPILOG = """examples:
  crowdmpc simulate --controller orca --scenario circle --humans 7 --episodes 20 --seed 0
  crowdmpc simulate --controller cmpc --predictor constant_velocity --scenario perpendicular --humans 5 \\
      --episodes 10 --json runs/cmpc.json --plot runs/cmpc.png --record runs/cmpc
  crowdmpc simulate --controller dmpc --no-flocking --coupling ibr --humans 9 --episodes 50
  crowdmpc --plugin my_predictor:MyNet simulate --controller cmpc --predictor my_net_eth --humans 7

Episode i uses seed S + i. --plot draws the first episode; --record writes one MCAP file per episode.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "simulate",
        help="run closed-loop episodes and print the paper's metrics",
        description="Run a robot controller in the ORCA crowd simulator and report success, travel time, "
        "collision, contact and discomfort rates and the cost of each control step.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--controller", required=True, choices=sorted(CONTROLLERS), help="robot controller")
    parser.add_argument(
        "--predictor",
        default="constant_velocity",
        help="predictor of cmpc/dmpc: a registered name or a model of the shipped or user zoo "
        "(default: %(default)s)",
    )
    parser.add_argument(
        "--scenario", default="circle", choices=sorted(SCENARIOS), help="default: %(default)s"
    )
    parser.add_argument("--humans", type=int, default=7, help=f"0..{MAX_HUMANS} (default: %(default)s)")
    parser.add_argument("--robots", type=int, default=3, help=f"1..{MAX_ROBOTS} (default: %(default)s)")
    parser.add_argument("--episodes", type=int, default=1, help="default: %(default)s")
    parser.add_argument("--seed", type=int, default=0, help="first episode's seed (default: %(default)s)")
    parser.add_argument("--no-flocking", action="store_true", help="omega_floc = 0 (Table III, NF)")
    parser.add_argument("--coupling", default="ibr", choices=COUPLINGS, help="default: %(default)s")
    parser.add_argument(
        "--margins",
        default="none",
        metavar="SPEC",
        help="allowance for prediction error in the robot-human distance: none (the paper, default), "
        "conformal[:ALPHA[:closed-loop|real]] (needs `crowdmpc calibrate`), fixed:M1,..,MH (metres)",
    )
    parser.add_argument(
        "--profile", default="paper", choices=sorted(PROFILES), help="simulation conventions (default: paper)"
    )
    parser.add_argument(
        "--visibility", default="visible", choices=VISIBILITY, help="robots seen by the humans' ORCA"
    )
    parser.add_argument("--json", type=Path, metavar="FILE", help="write the summary and per-episode records")
    parser.add_argument("--plot", type=Path, metavar="FILE", help="draw the first episode (PNG, PDF, SVG)")
    parser.add_argument("--record", type=Path, metavar="DIR", help="one MCAP file per episode in DIR")
    parser.add_argument(
        "--record-iterations", action="store_true", help="record every IBR iteration's prediction"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=run)


def _fmt(x: float | None, unit: str = "", digits: int = 2) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}{unit}"


def format_table(summary: dict[str, Any], header: str) -> str:
    n = summary["episodes"]

    def rate(name: str) -> str:
        return f"{summary[f'{name}_rate']:6.1f} %  ({summary[f'{name}_count']}/{n})"

    rows = [
        ("success", rate("success")),
        (
            "travel time",
            f"{_fmt(summary['travel_time_mean'], ' s')}  (mean over successes, std "
            f"{_fmt(summary['travel_time_std'], ' s')})",
        ),  # fmt: skip
        ("collision (<0.8 m)", rate("collision")),
        ("contact (<0.6 m)", rate("contact")),
        ("discomfort", rate("discomfort")),
        (
            "per step",
            f"collision {_fmt(summary.get('collision_step_freq'), ' %')}, contact "
            f"{_fmt(summary.get('contact_step_freq'), ' %')}, discomfort "
            f"{_fmt(summary.get('discomfort_step_freq'), ' %')} of states",
        ),  # fmt: skip
        ("timeout", rate("timeout")),
        (
            "min distance",
            f"{_fmt(summary['min_distance_mean'], ' m')} mean, "
            f"{_fmt(summary['min_distance_min'], ' m')} min (robot-human)",
        ),  # fmt: skip
        ("path length", f"{_fmt(summary['path_length_mean'], ' m')} mean per robot"),
        (
            "solve time",
            f"median {_fmt(summary['solve_time_median_ms'], ' ms')}, "
            f"p95 {_fmt(summary['solve_time_p95_ms'], ' ms')}, "
            f"max {_fmt(summary['solve_time_max_ms'], ' ms')} per control step",
        ),  # fmt: skip
        ("IBR iterations", f"mean {_fmt(summary['iterations_mean'])}, max {summary['iterations_max']}"),
        ("fallback steps", f"{summary['fallback_steps']} of {summary['control_steps']}"),
    ]
    width = max(len(name) for name, _ in rows)
    return "\n".join([header] + [f"  {name:<{width}}  {text}" for name, text in rows])


def _check(args: argparse.Namespace) -> None:
    if args.episodes < 1:
        raise PipelineError(f"--episodes must be >= 1, got {args.episodes}")
    if args.episodes > 100_000:  # a sweep's cell holds at most as many; beyond, use `crowdmpc sweep`
        raise PipelineError(f"--episodes must be at most 100000 (use crowdmpc sweep), got {args.episodes}")
    if not 1 <= args.robots <= MAX_ROBOTS:
        raise PipelineError(f"--robots must be in 1..{MAX_ROBOTS}, got {args.robots}")
    if args.seed < 0:
        raise PipelineError(f"--seed must be >= 0, got {args.seed}")
    if args.plot is not None:
        from crowdsim.plotting import check_figure_path

        check_figure_path(args.plot, "--plot")
    # Before the episodes, not after them: a path that cannot be written would waste the whole run.
    check_writable(args.json, "--json")
    check_writable(args.plot, "--plot")
    check_writable(args.record, "--record", directory=True)


def _run_meta(args: argparse.Namespace, spec: ControllerSpec) -> dict[str, Any]:
    """The command line's choices, for the JSON output and every MCAP file's "run" metadata."""
    return {
        "command": "simulate",
        "argv": sys.argv[1:],
        "controller": args.controller,
        "predictor": spec.predictor_name,
        "flocking": spec.flocking,
        "coupling": spec.coupling,
        "margins": spec.margins.label,
        "profile": args.profile,
        "visibility": args.visibility,
        "scenario": args.scenario,
        "humans": args.humans,
        "robots": args.robots,
        "episodes": args.episodes,
        "seed": args.seed,
    }


def run(args: argparse.Namespace) -> int:
    from crowdsim.profiles import make_env_config
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.episode import run_episodes, summarize
    from pipelines.loop.margins import parse_margins

    _check(args)
    spec = ControllerSpec(
        controller=args.controller,
        predictor=args.predictor,
        flocking=not args.no_flocking,
        coupling=args.coupling,
        record_iterations=args.record_iterations,
        margins=parse_margins(args.margins),
    )
    env_config = make_env_config(args.profile, args.visibility)
    run_meta = _run_meta(args, spec)
    recorder = None
    if args.record is not None:
        from pipelines.logs.recording import McapEpisodeRecorder

        recorder = McapEpisodeRecorder(
            args.record, record_iterations=args.record_iterations, run_meta=run_meta
        )
    try:
        results = run_episodes(
            spec,
            episodes=args.episodes,
            seed=args.seed,
            scenario=args.scenario,
            n_humans=args.humans,
            n_robots=args.robots,
            observers_factory=(lambda: (recorder,)) if recorder is not None else None,
            progress=not args.no_progress,
            env_config=env_config,
        )
    finally:
        if recorder is not None:
            recorder.close()

    summary = summarize(results)
    header = (
        f"controller {args.controller} | predictor {spec.predictor_name or '-'} | "
        f"margins {spec.margins.label} | "
        f"{args.profile}/{args.visibility} | scenario {args.scenario} | "
        f"humans {args.humans} | robots {args.robots} | episodes {args.episodes} | seeds {args.seed}.."
        f"{args.seed + args.episodes - 1}"
    )
    print(format_table(summary, header))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        payload = {"run": run_meta, "summary": summary, "episodes": [r.record().to_dict() for r in results]}
        args.json.write_text(json.dumps(plain(payload), indent=1) + "\n")
        print(f"wrote {args.json}")
    if args.plot is not None:
        _plot(args, results[0], env_config)
    if recorder is not None:
        print(f"wrote {len(recorder.paths)} MCAP file(s) to {args.record}")
    return 0


def _plot(args: argparse.Namespace, first: EpisodeResult, env_config: EnvConfig) -> None:
    from crowdsim.plotting import plot_episode

    m = first.metrics
    title = (
        f"{args.controller}, {args.scenario}, seed {first.seed}: "
        + (f"success in {m.travel_time:g} s" if m.success else "timeout")
        + f", min robot-human distance {m.min_distance:.2f} m"
    )
    fig = plot_episode(
        first.robot_positions,
        first.human_positions,
        first.robot_goals,
        title=title,
        radius=env_config.radius,
        dt=env_config.dt,
    )
    args.plot.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.plot, dpi=120, bbox_inches="tight")
    print(f"wrote {args.plot}")
