"""The MPC with sensors of limited range: personal space when humans come into view late, tracks given or not.

Every episode is run once with the simulator's full observation and, for each ``--radii`` R, twice through
``pipelines.loop.sensing.RangeLimited``: the controller sees only the humans within R metres of some robot,
a human's rows before it came into view are padded with its first tracked position, and the tracks'
lengths are given (``human_observed``: the MPC extends each short track back, ``predictors.backfill``) or
not (the padding then reads as the human's past: standing, then starting). Episodes are paired: the same
seeds and scenarios (circle and perpendicular in turn) in every row. Prints success and collision rates
(the paper's: a robot-human distance below 0.8 m), the collision rate with its 95 % Wilson interval, the
median smallest robot-human distance and the mean travel time of the successes. The metrics are the
simulator's, over every human.

    nice -n 5 .venv/bin/python benchmarks/sensor_range.py
    nice -n 5 .venv/bin/python benchmarks/sensor_range.py --config docs/examples/safe_crossing.toml --radii 3
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    check_distinct,
    episode_bar,
    episode_count,
    figure,
    human_count,
    json_on_stdout,
    output_file,
    predictor_name,
    run_main,
    seed_number,
    write_json,
)

SCENARIOS = ("circle", "perpendicular")


def radius(text: str) -> float:
    """An argparse ``type``: a sensor range in metres, > 0."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not value > 0 or math.isinf(value):
        raise argparse.ArgumentTypeError(
            f"a sensor radius must be a finite number of metres > 0, got {text!r}"
        )
    return value


def run_row(controller, label: str, episodes: int, seed: int, humans: int) -> dict[str, Any]:
    """``episodes`` episodes of ``controller``; the outcomes and their summary."""
    from pipelines.experiments.summary import wilson_interval
    from pipelines.loop.episode import run_episode

    outcomes = []
    for i in episode_bar(episodes, label):
        metrics = run_episode(
            controller, seed=seed + i // 2, scenario=SCENARIOS[i % 2], n_humans=humans
        ).metrics
        outcomes.append((metrics.success, metrics.collision, metrics.min_distance, metrics.travel_time))
    success, collision, distance, travel = np.array(outcomes, dtype=float).T
    return {
        "row": label,
        "episodes": episodes,
        "success_pct": 100 * success.mean(),
        "collision_pct": 100 * collision.mean(),
        "collision_95_pct": [100 * b for b in wilson_interval(int(collision.sum()), episodes)],
        "min_distance_median_m": float(np.median(distance)),
        "travel_mean_s": float(np.nanmean(travel)) if success.any() else None,
    }


def print_rows(rows: list[dict[str, Any]]) -> None:
    """The rows as a table; a median of no robot-human distance (no human: inf, null in the JSON) is "-"."""
    print(f"{'':<30}{'success %':>10}{'collision % (95 %)':>22}{'min dist m':>12}{'travel s':>10}")
    for row in rows:
        low, high = row["collision_95_pct"]
        travel = "-" if row["travel_mean_s"] is None else f"{row['travel_mean_s']:.2f}"
        collision = f"{row['collision_pct']:>8.0f} ({low:>4.0f}-{high:>3.0f})"
        print(f"{row['row']:<30}{row['success_pct']:>10.0f}{collision}"
              f"{figure(row['min_distance_median_m'], '>17.2f')}{travel:>10}")  # fmt: skip


def main() -> None:
    from pipelines.config import ConfigError, load
    from pipelines.errors import PipelineError
    from pipelines.loop.controllers import ControllerSpec, make_controller
    from pipelines.loop.margins import parse_margins
    from pipelines.loop.sensing import RangeLimited

    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--controller", choices=("cmpc", "dmpc"), default="cmpc")
    parser.add_argument("--predictor", type=predictor_name, default="social_lstm_eth")
    parser.add_argument(
        "--config",
        help="a crowdmpc config file: its [controller] margins and [mpc] table (default: the paper's)",
    )
    parser.add_argument("--radii", type=radius, nargs="+", default=[4.0, 3.0, 2.0])
    parser.add_argument("--humans", type=human_count, default=7)
    parser.add_argument("--episodes", type=episode_count, default=100, help="episodes per row")
    parser.add_argument("--seed", type=seed_number, default=0, help="episode i uses seed + i // 2")
    parser.add_argument("--json", type=output_file, help="write the rows to this file ('-': stdout)")
    args = parser.parse_args()
    check_distinct(parser, "--radii", args.radii)
    with json_on_stdout(args.json):
        try:  # the config files' parser and checks
            run = load(args.config)
            margins = parse_margins(run.controller.margins or "none")
            spec = ControllerSpec(
                args.controller, args.predictor, mpc_overrides=run.mpc_overrides(), margins=margins
            )
        except (ConfigError, PipelineError) as exc:
            parser.error(f"--config: {exc}")
        controller = make_controller(spec)
        controller.prepare(3, range(args.humans + 1))  # type: ignore[attr-defined]  # every crowd in view
        print(f"{args.controller}, {args.predictor}, margins {margins.label}"
              + "".join(f", {k}={v}" for k, v in spec.mpc_overrides)
              + f", {counted(args.humans, 'human')}, {counted(args.episodes, 'episode')} a row")  # fmt: skip
        rows = [run_row(controller, "full observation", args.episodes, args.seed, args.humans)]
        for r in args.radii:
            for report in (True, False):
                label = f"R = {r:g} m, tracks {'given' if report else 'not given'}"
                sensor = RangeLimited(controller, r, report_tracks=report)
                rows.append(run_row(sensor, label, args.episodes, args.seed, args.humans))
        controller.close()
        print_rows(rows)
    if args.json:
        write_json(args.json, {"controller": args.controller, "predictor": args.predictor, "rows": rows})


if __name__ == "__main__":
    raise SystemExit(run_main(main))
