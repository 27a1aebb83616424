"""Do the shipped conformal margins cover real people? Closed-loop episodes among each ``--crowds`` crowd,
scored as ``crowdmpc calibrate`` scores ORCA's (``pipelines.experiments.calibrate.PredictionErrors``: at each
step, the prediction the final solve used of every human within ``--near`` m of a robot, against where that
human was k steps later, while tracked), and the share of the scores within each ``--margins`` margin at
each horizon step k: the coverage, whose target is 1 - alpha.

``conformal:A`` and ``conformal:A:real`` score the displacement error against one margin per step (the
closed-loop calibration among ORCA's humans, the open-loop one on the TrajNet++ validation scenes);
``conformal-motion:A`` against its human's motion class's margin; ``conformal-shortfall:A`` (the safe
configuration's margins) scores the distance shortfall, how much closer a human came to a robot than
predicted, against its class's margin. The shipped closed-loop blocks were calibrated on seeds 1,000,000 to
1,000,099 among 5 to 9 ORCA humans, the same schedule as here (scenarios alternating, crowd sizes cycling);
this script's seeds start at 1,100,000 (``--seed``), so ``orca`` is a held-out check of the calibration and
each replayed crowd (docs/replayed_crowds.md) the question. The robots plan with ``--plan-with`` (default
``none``: the paper's method, as calibration runs). A replayed crowd's ``--humans`` count the people who come
by in an episode, not those there at once. ``--sensor-range M`` puts the robots behind a sensor of that range
(``pipelines.loop.sensing``): they see and predict the people within M m of a robot, from their tracks since
they came into view, and each is scored, and classed for the per-class margins, as the controller saw it.

    nice -n 5 .venv/bin/python benchmarks/replay_coverage.py --predictor social_lstm_eth --episodes 50
    nice -n 5 .venv/bin/python benchmarks/replay_coverage.py --predictor constant_velocity \\
        --crowds orca hotel_test --plan-with conformal-shortfall:0.05
    nice -n 5 .venv/bin/python benchmarks/replay_coverage.py --predictor social_lstm_eth --sensor-range 4
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from crowdsim.replay import CROWDS
from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    check_distinct,
    count_in,
    episode_bar,
    episode_count,
    figure,
    json_on_stdout,
    output_file,
    predictor_name,
    run_main,
    seed_number,
    write_json,
)

SEED = 1_100_000  # after the shipped calibrations' 1,000,000..1,000,099 and every evaluation seed
MARGINS = ("conformal:0.1", "conformal:0.1:real", "conformal-motion:0.1", "conformal-shortfall:0.05")


def scores(
    predictor: str,
    crowd: str,
    plan_with: str,
    episodes: int,
    humans: list[int],
    seed: int,
    near: float,
    sensor_range: float | None = None,
) -> tuple[Any, dict[str, Any]]:
    """The ``PredictionErrors`` of ``episodes`` CMPC episodes among ``crowd`` (behind a sensor of
    ``sensor_range`` m, None: none), on calibration's schedule (``ClosedLoopPlan.schedule``: scenarios
    alternating, crowd sizes cycling), and their outcome."""
    from crowdsim.profiles import make_env_config
    from pipelines.experiments.calibrate import ClosedLoopPlan, PredictionErrors
    from pipelines.loop.controllers import ControllerSpec, make_controller
    from pipelines.loop.episode import behind_sensor, run_episode
    from pipelines.loop.margins import parse_margins

    plan = ClosedLoopPlan(
        predictor, episodes, seed, tuple(humans), near=near, margins=parse_margins(plan_with)
    )
    env_config = dataclasses.replace(make_env_config(plan.profile, plan.visibility), crowd=crowd)
    controller = make_controller(
        ControllerSpec("cmpc", predictor, margins=plan.margins).behind(sensor_range), env_config
    )
    # among a replayed crowd, shown the people tracked now, its NLP of every count built first
    controller = behind_sensor(controller, sensor_range, True, 3, max(plan.humans), crowd)
    observer = PredictionErrors(plan.near)
    outcome = {"episodes": episodes, "success": 0, "collision": 0}
    schedule = plan.schedule()
    try:
        for i in episode_bar(episodes, crowd):
            scenario, n_humans, episode_seed = schedule[i]
            result = run_episode(
                controller,
                seed=episode_seed,
                scenario=scenario,
                n_humans=n_humans,
                env_config=env_config,
                observers=(observer,),
            )
            outcome["success"] += int(result.metrics.success)
            outcome["collision"] += int(result.metrics.collision)
    finally:
        controller.close()
    return observer, outcome


def coverage(observer: Any, margins: str, predictor: str, horizon: int) -> list[float]:
    """The share of ``observer``'s scores within ``margins`` at each horizon step (NaN: nothing scored)."""
    from pipelines.loop.margins import parse_margins
    from predictors.conformal import COVERAGE_TOLERANCE
    from predictors.registry import checkpoint_sha256

    spec = parse_margins(margins)
    sha256 = checkpoint_sha256(predictor)
    table = spec.resolve_classes(predictor, horizon, sha256)
    score = observer.shortfall if spec.mode == "conformal-shortfall" else observer.errors
    if not len(score):  # no human came within --near of a robot: PredictionErrors' empty (0, 0), no steps
        return [math.nan] * horizon
    if table is None:
        bound = np.broadcast_to(np.asarray(spec.resolve(predictor, horizon, sha256)), score.shape)
    else:
        bound = np.asarray(table.quantiles)[observer.classes][:, :horizon]
    known = ~np.isnan(score)
    within = (score <= bound + COVERAGE_TOLERANCE) & known  # as calibrate counts (predictors.conformal)
    counts = known.sum(axis=0)
    return [float(w / c) if c else math.nan for w, c in zip(within.sum(axis=0), counts, strict=True)]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--predictor", type=predictor_name, default="social_lstm_eth")
    parser.add_argument("--crowds", nargs="+", choices=CROWDS, default=["orca", "eth_test", "hotel_test"])
    parser.add_argument("--margins", nargs="+", default=list(MARGINS), help="margins whose coverage is shown")
    parser.add_argument("--plan-with", default="none", help="the margins the robots plan with (default none)")
    parser.add_argument("--episodes", type=episode_count, default=50, help="episodes per crowd")
    parser.add_argument("--humans", nargs="+", type=count_in("humans", 1, 50), default=[5, 6, 7, 8, 9])
    parser.add_argument("--seed", type=seed_number, default=SEED)
    parser.add_argument("--near", type=float, default=3.0, help="m: humans scored within this of a robot")
    parser.add_argument(
        "--sensor-range",
        type=float,
        default=None,
        metavar="M",
        help="m: the robots see this far (default: all)",
    )
    parser.add_argument("--json", type=output_file, default=None, metavar="FILE")
    args = parser.parse_args()
    from crowdsim.world import is_sensor_range
    from pipelines.loop.margins import parse_margins

    if args.sensor_range is not None and not is_sensor_range(args.sensor_range):
        parser.error(f"--sensor-range must be a finite number of metres > 0, got {args.sensor_range}")
    for text in (*args.margins, args.plan_with):
        parse_margins(text)  # a typo is one line now, not after the episodes
    # the report is keyed by both: a repeat ran (or scored) twice and was printed and written once
    check_distinct(parser, "--crowds", args.crowds)
    check_distinct(parser, "--margins", args.margins)
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        _measure(args)


def _measure(args: argparse.Namespace) -> None:
    from mpc.config import MPCConfig

    horizon = MPCConfig().horizon
    report: dict[str, Any] = {
        "predictor": args.predictor,
        "plan_with": args.plan_with,
        "sensor_range": args.sensor_range,
        "crowds": {},
    }
    for crowd in args.crowds:
        observer, outcome = scores(
            args.predictor,
            crowd,
            args.plan_with,
            args.episodes,
            args.humans,
            args.seed,
            args.near,
            args.sensor_range,
        )
        shares = {margins: coverage(observer, margins, args.predictor, horizon) for margins in args.margins}
        scored = int(np.isfinite(observer.errors[:, 0]).sum()) if observer.errors.size else 0
        report["crowds"][crowd] = {**outcome, "scored_at_k1": scored, "coverage": shares}
    print_report(report, horizon)
    if args.json is not None:
        write_json(args.json, report)


def print_report(report: dict[str, Any], horizon: int) -> None:
    sensor = report.get("sensor_range")
    behind = f", behind a sensor of {sensor:g} m" if sensor is not None else ""
    print(
        f"{report['predictor']}, planning with margins {report['plan_with']}{behind}: coverage at k = "
        f"1..{horizon} (target 1 - alpha)"
    )
    for crowd, measured in report["crowds"].items():
        print(
            f"{crowd}: {counted(measured['episodes'], 'episode')}, {measured['success']} "
            f"success{'es' * (measured['success'] != 1)}, {measured['collision']} with a collision; "
            f"{counted(measured['scored_at_k1'], 'score')} at k = 1 (a human at a step)"
        )
        for margins, shares in measured["coverage"].items():
            print(f"  {margins:28s}" + " ".join(figure(share, "6.3f") for share in shares))


if __name__ == "__main__":
    sys.exit(run_main(main))
