"""Robots trading places: M robots on a circle, each bound for the point opposite its start, among N people.

The antipodal circle is the multi-robot test a newcomer writes first (two robots swapping places is M = 2):
every robot's straight line runs through the centre, so the team must share it, and with exact coordinates
each robot meets the one opposite it exactly head-on. Each row runs one controller on one team size; with
``--jitter`` every start and goal moves by up to that many metres (episode i draws from seed + i), so rows
show both the exact layout and the ones a real team would see. ``--humans N`` adds people by the paper's
crossing rules (``--scenario``: circle or perpendicular, each placed clear of the robots' starts and goals,
drawn from the episode's seed). It prints success, travel time, the closest two robots came (centres; 2 x
radius is contact), robot-human collisions (< 0.8 m, Table I's), the time-outs and, among them, the
deadlocks (no robot moved 5 cm in the last 10 s): two robots in the exact swap deadlock under every
controller unless ``--jitter`` moves the tie (ORCA) or ``--mpc flock_range=2`` lets them out of Eq. 15 (the
MPCs; with the jitter alone the flocking pair arrives together at one goal, then the other).

    nice -n 5 .venv/bin/python benchmarks/robot_swaps.py --robots 2 3 4 6 --controllers cmpc dmpc orca
    nice -n 5 .venv/bin/python benchmarks/robot_swaps.py --robots 2 4 --jitter 0.05 --episodes 10 \\
        --mpc flock_range=2
    nice -n 5 .venv/bin/python benchmarks/robot_swaps.py --robots 3 4 --humans 5 --episodes 20 \\
        --mpc flock_range=2 --config docs/examples/safe_crossing.toml
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path
from typing import Any, Final

import gymnasium as gym
import numpy as np

import crowdsim
from crowdsim.crossings import place_humans_paper
from crowdsim.env_config import EnvConfig
from crowdsim.formations import antipodal_circle
from crowdsim.scenarios import MAX_TRIES, SCENARIOS, Layout, geometry_scale
from pipelines.config import ConfigError, load
from pipelines.errors import FlockWarning, PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.gym_loop import run_gym_episode
from pipelines.loop.margins import MarginSpec, parse_margins

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    check_distinct,
    check_not_input,
    count_in,
    episode_bar,
    episode_count,
    human_count,
    json_on_stdout,
    mpc_sets,
    output_file,
    run_main,
    seed_number,
    write_json,
)

CONTROLLERS = ("cmpc", "dmpc", "orca")
MAX_JITTER = 0.5  # m per coordinate; main() refuses a circle too small for its robots so moved
# A time-out in which no robot moved STILL_M in the episode's last STILL_S is a deadlock, not a slow arrival:
# the exact swap of two robots ends so, the MPCs' pair held 1.42 m apart in the middle by Eq. 15 (their goal
# pulls cancel to the last bit) and ORCA's pair face to face, each to the millimetre.
STILL_S: Final[float] = 10.0  # s, a quarter of the 40 s episode
STILL_M: Final[float] = 0.05  # m in STILL_S: 0.5 % of walking at v_pref (1 m/s)
DEADLOCK_NOTE = (
    "deadlock: timed out with no robot moving {still_m:g} m in the last {still_s:g} s. In the exact swap of "
    "two robots ORCA's pair meets head-on and stops, and Eq. 15 (every pair flocking) holds the MPCs' pair "
    "together in the middle, their goal pulls cancelling: --jitter moves the tie, --mpc flock_range=2 frees "
    "them"
)


def antipodal(
    n_robots: int,
    radius: float,
    jitter: float,
    rng: np.random.Generator,
    n_humans: int = 0,
    scenario: str = "circle",
) -> Layout:
    """Robot i starts at angle ``-pi/2 + 2 pi i / M`` on the circle and heads for the opposite point; each
    start and goal then moves by a uniform draw in ``[-jitter, jitter]`` per coordinate; ``n_humans`` people
    are placed after them by the paper's crossing rules (``EnvConfig()``'s radius and separation)."""
    starts, goals = antipodal_circle(n_robots, radius)
    if jitter > 0:
        starts = starts + rng.uniform(-jitter, jitter, starts.shape)
        goals = goals + rng.uniform(-jitter, jitter, goals.shape)
    config = EnvConfig()
    people = place_humans_paper(
        scenario,
        n_humans,
        starts,
        goals,
        rng,
        min_dist=2 * config.radius + config.spawn_separation,
        v_pref=config.v_pref,
        scale=geometry_scale(n_humans),
        max_tries=MAX_TRIES,
    )
    human_starts, human_goals = (np.asarray(p, dtype=float).reshape(n_humans, 2) for p in people)
    return Layout(starts, goals, human_starts, human_goals)


def run_row(
    controller: str,
    n_robots: int,
    args: argparse.Namespace,
    overrides: tuple[tuple[str, Any], ...],
    margins: MarginSpec,
) -> dict[str, Any]:
    """``args.episodes`` episodes of one controller with ``n_robots`` robots: the row's figures."""
    config = EnvConfig()
    env = gym.make(crowdsim.ENV_ID, n_humans=args.humans, n_robots=n_robots, config=config)
    spec = ControllerSpec(controller, mpc_overrides=overrides, margins=margins)
    policy = make_controller(spec if controller != "orca" else ControllerSpec(controller), config)
    outcomes = []
    try:
        for i in episode_bar(args.episodes, f"{controller} M={n_robots}"):
            rng = np.random.default_rng(args.seed + i)
            layout = antipodal(n_robots, args.radius, args.jitter, rng, args.humans, args.scenario)
            result = run_gym_episode(policy, env, seed=args.seed + i, options={"layout": layout})
            m = result.metrics
            still = m.timeout and stood_still(result.robot_positions, config.dt)
            outcomes.append((m.success, m.travel_time, m.min_distance_robots, m.collision, m.timeout, still))
    finally:
        policy.close()
        env.close()
    columns = (np.array(column, dtype=float) for column in zip(*outcomes, strict=True))
    success, travel, closest, collision, timeout, deadlock = columns
    return {
        "controller": controller,
        "robots": n_robots,
        "episodes": args.episodes,
        # % of the episodes, as every other *_rate the project writes (docs/outputs.md's conventions)
        "success_rate": 100 * float(success.mean()),
        "travel_time_mean": float(travel[success > 0].mean()) if success.any() else math.nan,
        "min_robot_distance": float(closest.min()),
        "contact_rate": 100 * float((closest < 2 * config.radius).mean()),
        "humans": args.humans,
        "collision_rate": 100 * float(collision.mean()),
        "timeout_rate": 100 * float(timeout.mean()),
        "deadlock_rate": 100 * float(deadlock.mean()),
    }


def stood_still(positions: np.ndarray, dt: float) -> bool:
    """Whether no robot of ``positions`` ``(T+1, M, 2)`` m moved ``STILL_M`` over the last ``STILL_S``."""
    steps = round(STILL_S / dt)
    if len(positions) <= steps:
        return False
    moved = np.linalg.norm(positions[-1] - positions[-1 - steps], axis=-1)
    return bool(np.all(moved < STILL_M))


def print_rows(rows: list[dict[str, Any]], radius: float) -> None:
    print(
        f"{'controller':10s} {'M':>3s} {'eps':>4s} {'success':>8s} {'travel s':>9s} {'closest m':>10s} "
        f"{'contact':>8s} {'N':>3s} {'collision':>9s} {'timeout':>8s} {'deadlock':>9s}"
    )
    for r in rows:
        travel = "n/a" if math.isnan(r["travel_time_mean"]) else f"{r['travel_time_mean']:.1f}"
        print(
            f"{r['controller']:10s} {r['robots']:3d} {r['episodes']:4d} {r['success_rate']:7.0f}% "
            f"{travel:>9s} {r['min_robot_distance']:10.2f} {r['contact_rate']:7.0f}% {r['humans']:3d} "
            f"{r['collision_rate']:8.0f}% {r['timeout_rate']:7.0f}% {r['deadlock_rate']:8.0f}%"
        )
    print(
        f"(closest: the smallest centre distance of two robots in the row; contact below {2 * radius:g} m; "
        "collision: a robot within 0.8 m of a person)"
    )
    if any(r["deadlock_rate"] for r in rows):
        print(f"({DEADLOCK_NOTE.format(still_m=STILL_M, still_s=STILL_S)})")


def jitter_metres(text: str) -> float:
    value = float(text)
    if not 0 <= value <= MAX_JITTER:
        raise argparse.ArgumentTypeError(f"must be in [0, {MAX_JITTER}] m, got {text}")
    return value


def circle_radius(text: str) -> float:
    value = float(text)
    if not 1.0 <= value <= 10.0:
        raise argparse.ArgumentTypeError(f"must be in [1, 10] m (the paper's arena is 5 m), got {text}")
    return value


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--robots", type=count_in("--robots", 2, 12), nargs="+", default=[2, 3, 4, 6])
    parser.add_argument("--controllers", nargs="+", choices=CONTROLLERS, default=list(CONTROLLERS))
    parser.add_argument("--radius", type=circle_radius, default=4.0, help="m, the circle's (default 4)")
    parser.add_argument(
        "--jitter", type=jitter_metres, default=0.0, help="m per coordinate (default 0: exact)"
    )
    parser.add_argument("--humans", type=human_count, default=0, help="people crossing too (default 0)")
    parser.add_argument("--scenario", choices=SCENARIOS, default="circle", help="the people's crossing")
    parser.add_argument("--episodes", type=episode_count, default=1, help="episodes per row (default 1)")
    parser.add_argument(
        "--seed", type=seed_number, default=0, help="episode i draws its jitter from seed + i"
    )
    parser.add_argument(
        "--mpc",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an [mpc] value, as `crowdmpc --set mpc.KEY=VALUE` takes it, for cmpc and dmpc (repeatable)",
    )
    parser.add_argument(
        "--config", help="a crowdmpc config file: its [mpc] table and [controller] margins, for cmpc and dmpc"
    )
    parser.add_argument("--json", type=output_file, help="also write the rows to this file")
    args = parser.parse_args(argv)
    # the rows where every pair flocks are the point: the controller's note on them, once an episode, is not
    warnings.simplefilter("ignore", FlockWarning)
    with json_on_stdout(args.json):
        check_not_input(parser, "--json", args.json, [args.config])  # a typo must not overwrite the config
        check_distinct(parser, "--robots", args.robots)
        # neighbours' starts (and goals) a chord apart, less what the jitter may take off each (its
        # diagonal), must leave room for two bodies
        body = 2 * EnvConfig().radius + 2 * math.sqrt(2) * args.jitter
        for m in args.robots:
            gap = 2 * args.radius * math.sin(math.pi / m)
            if gap < body:
                parser.error(
                    f"--radius {args.radius:g} puts {m} robots {gap:.2f} m apart, too close for two robots' "
                    f"bodies moved by --jitter {args.jitter:g} ({body:.2f} m): a radius of at least "
                    f"{body / 2 / math.sin(math.pi / m):.2f} m"
                )
        try:
            run = load(args.config, sets=mpc_sets(args.mpc))
            overrides, margins = run.mpc_overrides(), parse_margins(run.controller.margins or "none")
        except (ConfigError, PipelineError) as exc:
            parser.error(f"--config/--mpc: {exc}")
        rows = [run_row(c, m, args, overrides, margins) for c in args.controllers for m in args.robots]
        print_rows(rows, EnvConfig().radius)
        if args.json is not None:
            write_json(args.json, {"args": vars(args), "rows": rows})


if __name__ == "__main__":
    sys.exit(run_main(main))
