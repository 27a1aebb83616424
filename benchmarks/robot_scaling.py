r"""Success, collision, travel time and control-step time against the number of robots.

For every number of robots M (``--robots``, default 3 5 6 12) and controller (``--controllers``, default CMPC
and DMPC with ``--predictor``, default constant velocity), ``--episodes`` episodes (default 50) with
``--humans`` humans (default 7) under the paper profile: episode ``i`` runs scenario ``circle`` for even
``i`` and ``perpendicular`` for odd ``i`` (``--scenarios`` to change), seed ``--seed + i``. The robots stand
in ``--formation`` (default: the config's ``[env] formation``, else ``auto``,
crowdsim.formations.choose_formation); episode ``i`` is ``CrowdEnv(EnvConfig(formation=...)).reset(seed,
scenario, humans, M)`` under the paper profile. ``--formation row`` gives the first layout (1 m row, goals
10 m north) for a before/after comparison.

Per row: success, collision (robot-human below d_min) and timeout rates in %, mean travel time over the
successful episodes, the smallest robot-robot distance, the robots that reached their goals (% of all), and
the control step (``ControlOutput.solve_time_s``: prediction, every solve and the IBR bookkeeping) as median /
p95 / p99 in ms over every step of every episode, with the steps that ran to j_max IBR iterations and those
that fell back (braking); when the flock was half-way (``halfway_s``, median over the successful and over the
failed episodes that got half-way: a failure that gets there late was held up crossing, one that gets there in
time lost the end); and the failed episodes by how they ended (``failure_kind``: every robot arrived but some
were pushed off again, a robot stuck short of its goal, or robots still closing in at the limit). The machine
is shared: the load average is printed; run it under ``nice`` and repeat when the figures look noisy.

    nice -n 5 .venv/bin/python benchmarks/robot_scaling.py                       # 50 episodes a row
    nice -n 5 .venv/bin/python benchmarks/robot_scaling.py --episodes 4 --controllers cmpc --robots 3 6 12
    nice -n 5 .venv/bin/python benchmarks/robot_scaling.py --formation row --json before.json
    nice -n 5 .venv/bin/python benchmarks/robot_scaling.py --mpc stall_release_s=4 --robots 12
    nice -n 5 .venv/bin/python benchmarks/robot_scaling.py --controllers dmpc --mpc dmpc_update=gauss_seidel
    nice -n 5 .venv/bin/python benchmarks/robot_scaling.py --config docs/examples/safe_crossing.toml \
        --mpc on_goal=yield

``--config`` reads a config file's ``[mpc]`` table, ``[controller]`` margins and ``[env]`` goal_assignment
and formation (``crowdmpc --config``), the ``--mpc`` values applied over it; ``--goals`` and ``--formation``
win over the file. ``--goals slots`` makes the goals a formation to fill (crowdsim/slots.py) instead of one
fixed goal per robot (the paper's task, the default); the two are different tasks, so their rows are reported
side by side, never as one.

    nice -n 5 .venv/bin/python benchmarks/robot_scaling.py --config docs/examples/many_robots.toml \
        --goals slots --controllers cmpc
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, cast

import numpy as np

from crowdsim.env import CrowdEnv
from crowdsim.errors import SimulationError
from crowdsim.formations import FORMATIONS, Formation, choose_formation
from crowdsim.metrics import EpisodeMetrics, Trajectory, aggregate, episode_metrics
from crowdsim.profiles import make_env_config
from crowdsim.scenarios import SCENARIOS
from crowdsim.slots import GOAL_ASSIGNMENTS, GoalAssignment
from pipelines.config import ConfigError, load
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.margins import MarginSpec, parse_margins
from pipelines.loop.mpc import MPCController
from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    check_distinct,
    check_not_input,
    episode_bar,
    episode_count,
    figure,
    human_count,
    json_on_stdout,
    mpc_sets,
    output_file,
    predictor_name,
    robot_count,
    run_main,
    seed_number,
    write_json,
)

CONTROLLERS = ("cmpc", "dmpc")
# What this project adds for many robots, beside the paper's method: one source, the example config file
# (benchmarks/run_all.py's robots section runs both).
MANY_ROBOTS_TOML = Path(__file__).resolve().parents[1] / "docs" / "examples" / "many_robots.toml"


def many_robots() -> tuple[tuple[tuple[str, Any], ...], MarginSpec]:
    """docs/examples/many_robots.toml's MPC overrides and margins."""
    run = load(str(MANY_ROBOTS_TOML))
    return run.mpc_overrides(), parse_margins(run.controller.margins or "none")


def step_stats(seconds: list[float]) -> dict[str, float]:
    """Median, 95th and 99th percentile of control-step wall times, in ms."""
    ms = np.asarray(seconds, dtype=float) * 1e3
    if ms.size == 0:
        return {"median_ms": math.nan, "p95_ms": math.nan, "p99_ms": math.nan}
    return {
        "median_ms": float(np.median(ms)),
        "p95_ms": float(np.percentile(ms, 95)),
        "p99_ms": float(np.percentile(ms, 99)),
    }


FAILURES = ("pushed_off", "stuck", "late")
CLOSING_WINDOW_S = 10.0  # s, how far back "still closing in" looks
CLOSING_M = 0.5  # m, the progress over that window that counts as closing in


def failure_kind(trajectory: Trajectory, metrics: EpisodeMetrics) -> str | None:
    """Why a failed episode failed, from its end (None for a success). Robots that never reached their goals
    decide first: ``stuck``, one of them came less than CLOSING_M m closer to it over the last
    CLOSING_WINDOW_S s; ``late``, all of them were still closing in when time ran out. ``pushed_off``: every
    robot off its goal at the end had reached it before (they arrived, but never all at once)."""
    if metrics.success:
        return None
    offset = np.linalg.norm(trajectory.robot_positions - trajectory.robot_goals[None], axis=-1)  # (T+1, M)
    off = offset[-1] >= trajectory.radius
    never = off & ~np.isfinite(np.asarray(metrics.reach_times))
    if not never.any():
        return "pushed_off"
    before = offset[max(0, len(offset) - 1 - round(CLOSING_WINDOW_S / trajectory.dt))]
    if (never & (before - offset[-1] < CLOSING_M)).any():
        return "stuck"
    return "late"


def halfway_s(trajectory: Trajectory) -> float:
    """When the robots' mean distance to their goals first fell to half its start (s; NaN if it never did):
    with the travel time, it splits an episode into the crossing and the arrival."""
    offsets = trajectory.robot_positions - trajectory.robot_goals[None]
    remaining = np.linalg.norm(offsets, axis=-1).mean(axis=1)
    below = np.flatnonzero(remaining <= 0.5 * remaining[0])
    return float(below[0] * trajectory.dt) if below.size else math.nan


def _median(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.median(finite)) if finite else math.nan


def run_row(
    controller: str,
    predictor: str,
    n_robots: int,
    n_humans: int,
    episodes: int,
    seed: int,
    scenarios: tuple[str, ...],
    formation: str,
    mpc_overrides: tuple[tuple[str, Any], ...] = (),
    margins: MarginSpec | None = None,
    goals: GoalAssignment = "fixed",
) -> dict[str, Any]:
    """``episodes`` episodes of one controller with ``n_robots`` robots: the row's figures."""
    env_config = dataclasses.replace(
        make_env_config("paper"),
        goal_assignment=goals,
        formation=cast(Formation, formation),  # one of FORMATIONS (argparse's choices; EnvConfig checks)
    )
    # reset, not reset_layout: the same layouts as make_layout with env_config's settings, without the
    # LayoutWarning reset_layout gives the paper perpendicular sampler's overlapping starts
    # (crowdsim.scenarios).
    env = CrowdEnv(env_config)
    spec = ControllerSpec(controller, predictor, mpc_overrides=mpc_overrides, margins=margins or MarginSpec())
    mpc = MPCController(spec, distributed=controller == "dmpc")
    metrics, times, iterations, fallbacks = [], [], [], 0
    kinds: list[str | None] = []
    halfway: list[float] = []
    t0 = time.perf_counter()
    try:
        for i in episode_bar(episodes, f"{controller} M={n_robots} N={n_humans} {goals}"):
            obs = env.reset(seed + i, scenarios[i % len(scenarios)], n_humans, n_robots)
            mpc.reset(obs)
            done = False
            while not done:
                out = mpc.act(obs)
                times.append(out.solve_time_s)
                iterations.append(out.iterations)
                fallbacks += out.fallback is not None
                obs, done, _ = env.step(out.accelerations)
            trajectory = env.trajectory()
            metrics.append(episode_metrics(trajectory))
            kinds.append(failure_kind(trajectory, metrics[-1]))
            halfway.append(halfway_s(trajectory))
    finally:
        mpc.close()
    agg = aggregate(metrics)
    reached = [np.isfinite(m.reach_times).mean() for m in metrics]
    return {
        "controller": controller,
        "robots": n_robots,
        "formation": choose_formation(n_robots) if formation == "auto" else formation,
        "goals": goals,
        "episodes": episodes,
        "success_rate": agg["success_rate"],
        "collision_rate": agg["collision_rate"],
        "timeout_rate": agg["timeout_rate"],
        "travel_time_mean": agg["travel_time_mean"],
        "min_distance_robots": float(min(m.min_distance_robots for m in metrics)),
        "reached_pct": 100.0 * float(np.mean(reached)),
        "steps": len(times),
        "j_max_steps": int(sum(it >= mpc.cfg.j_max for it in iterations)),
        "fallback_steps": fallbacks,
        "failures": {kind: kinds.count(kind) for kind in FAILURES},
        "halfway_s_success": _median([h for h, k in zip(halfway, kinds, strict=True) if k is None]),
        "halfway_s_failed": _median([h for h, k in zip(halfway, kinds, strict=True) if k is not None]),
        # episode i's outcome ("success" or its failure kind), for paired comparisons on the same crowds
        "outcomes": [kind or "success" for kind in kinds],
        **step_stats(times),
        "wall_s": time.perf_counter() - t0,
    }


def print_table(rows: list[dict[str, Any]]) -> None:
    head = (
        f"{'ctrl':<5} {'M':>3} {'formation':<9} {'goals':<5} {'succ%':>6} {'coll%':>6} {'tout%':>6} "
        f"{'travel s':>8} {'min rr m':>8} {'reach%':>6} {'med ms':>7} {'p95 ms':>7} {'p99 ms':>7} "
        f"{'steps':>6} {'j_max':>5} {'fallb':>5} {'half s ok/failed':>16}  "
        "failures: pushed off / stuck / late"
    )
    print(head)
    for r in rows:
        print(
            f"{r['controller']:<5} {r['robots']:>3} {r['formation']:<9} {r['goals']:<5} "
            f"{r['success_rate']:6.1f} {r['collision_rate']:6.1f} {r['timeout_rate']:6.1f} "
            f"{figure(r['travel_time_mean'], '8.2f')} "
            f"{figure(r['min_distance_robots'], '8.2f')} {r['reached_pct']:6.1f} {r['median_ms']:7.1f} "
            f"{r['p95_ms']:7.1f} {r['p99_ms']:7.1f} {r['steps']:6d} {r['j_max_steps']:5d} "
            f"{r['fallback_steps']:5d} {figure(r['halfway_s_success'], '7.1f')} / "
            f"{figure(r['halfway_s_failed'], '6.1f')}  "
            + " / ".join(str(r["failures"][kind]) for kind in FAILURES)
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--robots", type=robot_count, nargs="+", default=[3, 5, 6, 12])
    parser.add_argument("--controllers", nargs="+", choices=CONTROLLERS, default=list(CONTROLLERS))
    parser.add_argument("--predictor", type=predictor_name, default="constant_velocity")
    parser.add_argument("--humans", type=human_count, default=7)
    parser.add_argument("--episodes", type=episode_count, default=50, help="episodes per row (default 50)")
    parser.add_argument("--seed", type=seed_number, default=0, help="episode i uses seed + i")
    parser.add_argument("--scenarios", nargs="+", choices=SCENARIOS, default=list(SCENARIOS))
    parser.add_argument(
        "--formation", choices=FORMATIONS, help="the robots' formation; default: the config's, else auto"
    )
    parser.add_argument(
        "--mpc",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an [mpc] value as `crowdmpc --set mpc.KEY=VALUE` takes it, e.g. stall_release_s=4 or "
        "dmpc_update=gauss_seidel (repeatable)",
    )
    parser.add_argument(
        "--config",
        help="a crowdmpc config file: its [mpc] table, [controller] margins, [env] goal_assignment and "
        "formation",
    )
    parser.add_argument(
        "--goals",
        choices=GOAL_ASSIGNMENTS,
        help="fixed (the paper) | slots; default: the config's, else fixed",
    )
    parser.add_argument(
        "--json", type=output_file, help="also write the rows, with every episode's outcome, to this file"
    )
    args = parser.parse_args(argv)
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        check_not_input(parser, "--json", args.json, [args.config])
        check_distinct(parser, "--robots", args.robots)  # a repeat ran its row twice
        try:  # the config files' parser and checks: the values that differ from Table I, validated
            run = load(args.config, sets=mpc_sets(args.mpc))
            overrides = run.mpc_overrides()
            margins = parse_margins(run.controller.margins or "none")
            goals = args.goals or run.env.goal_assignment
            formation = args.formation or run.env.formation
        except (ConfigError, PipelineError) as exc:
            parser.error(f"--config/--mpc: {exc}")
        try:  # a pair refused together (the antipodal formation's goals as slots), named as typed here
            dataclasses.replace(make_env_config("paper"), goal_assignment=goals, formation=formation)
        except SimulationError as exc:
            parser.error(f"--formation {formation} with --goals {goals} (or the --config's [env]): {exc}")

        report: dict[str, Any] = {"load_before": os.getloadavg(), "args": vars(args)}
        rows = []
        for controller in args.controllers:
            for m in args.robots:
                rows.append(
                    run_row(
                        controller,
                        args.predictor,
                        m,
                        args.humans,
                        args.episodes,
                        args.seed,
                        tuple(args.scenarios),
                        formation,
                        overrides,
                        margins,
                        goals,
                    )
                )
        report["load_after"] = os.getloadavg()
        report["rows"] = rows

        print(
            f"predictor {args.predictor}, {counted(args.humans, 'human')}, "
            f"{counted(args.episodes, 'episode')} per row "
            f"({'/'.join(args.scenarios)}), formation {formation}, goals {goals}, margins {margins.label}"
            + "".join(f", {k}={v}" for k, v in overrides)
        )
        print(f"load average before {report['load_before'][0]:.2f}, after {report['load_after'][0]:.2f}")
        print_table(rows)
        if args.json:
            write_json(args.json, report)
        return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
