"""Time of one simulator step (``CrowdEnv.step``: ORCA for every human + the robots' double integrator).

For each crowd size, seeded circle-crossing episodes are run with ORCA-driven robots and every ``env.step``
is timed (the robots' controller is not); the states are those of real episodes, so the crowd is dense when
it meets in the middle. Each step is timed ``--repeats`` times on copies of the environment and the fastest
run kept, so that a busy machine's preemptions do not pass for simulator cost. Reports median, p95 and mean
per step, the ORCA velocity computation alone for the same states, and the share of steps where some human
needed RVO2's 3-D linear program.

    nice -n 10 .venv/bin/python benchmarks/orca_step.py
    nice -n 10 .venv/bin/python benchmarks/orca_step.py --humans 5 9 20 50 --robots 3 --episodes 10
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

import numpy as np

from crowdsim.baselines import OrcaController
from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from crowdsim.orca import orca_velocities, preferred_velocities
from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import check_distinct, count_in, episode_count, human_count, robot_count, run_main  # noqa: E402


def fastest(fn, repeats: int) -> float:
    """The shortest of ``repeats`` timed calls of ``fn()``, in seconds."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def measure(n_humans: int, n_robots: int, episodes: int, scenario: str, repeats: int) -> dict[str, float]:
    cfg = EnvConfig()
    env = CrowdEnv(cfg)
    controller = OrcaController()
    step_s: list[float] = []
    orca_s: list[float] = []
    lp3_steps = 0
    for seed in range(episodes):
        obs = env.reset(seed, scenario, n_humans, n_robots)
        controller.reset(obs)  # the controllers' protocol (a no-op for ORCA): MPCController warns without it
        done = False
        while not done:
            action = controller.act(obs).accelerations
            # The ORCA part alone, on the same state (what the step computes for the humans).
            positions = np.concatenate([obs.robot_positions, obs.human_positions])
            velocities = np.concatenate([obs.robot_velocities, obs.human_velocities])
            humans = np.arange(n_robots, n_robots + n_humans)

            def orca_only(obs=obs, positions=positions, velocities=velocities, humans=humans):
                pref = preferred_velocities(obs.human_positions, obs.human_goals, cfg.v_pref, cfg.radius)
                r = cfg.radius + cfg.orca_radius_margin
                orca_velocities(positions, velocities, pref, r, cfg.v_pref, cfg.orca, cfg.dt, agents=humans)

            copies = [copy.deepcopy(env) for _ in range(repeats)]
            step_s.append(fastest(lambda copies=copies, action=action: copies.pop().step(action), repeats))
            orca_s.append(fastest(orca_only, repeats))
            obs, done, info = env.step(action)
            lp3_steps += info["orca_lp3"] > 0
    ms = np.array(step_s) * 1e3
    return {
        "steps": len(ms),
        "median_ms": float(np.median(ms)),
        "p95_ms": float(np.percentile(ms, 95)),
        "mean_ms": float(ms.mean()),
        "orca_median_ms": float(np.median(orca_s) * 1e3),
        "lp3_share": lp3_steps / len(ms),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--humans", type=human_count, nargs="+", default=[5, 9, 20, 50])
    parser.add_argument("--robots", type=robot_count, default=3)
    parser.add_argument("--episodes", type=episode_count, default=10)
    parser.add_argument("--scenario", default="circle", choices=("circle", "perpendicular"))
    parser.add_argument(
        "--repeats", type=count_in("repeats", 1), default=3, help="timed runs per step; the fastest is kept"
    )
    args = parser.parse_args(argv)
    check_distinct(parser, "--humans", args.humans)  # a repeat ran its row twice
    print(
        f"CrowdEnv.step, {args.scenario} crossing, {counted(args.robots, 'ORCA robot')}, "
        f"{counted(args.episodes, 'episode')} a size"
    )
    print(f"{'humans':>6} {'agents':>6} {'steps':>6} {'median ms':>10} {'p95 ms':>8} {'mean ms':>8} "
          f"{'ORCA only ms':>13} {'3-D LP steps':>13}")  # fmt: skip
    for n in args.humans:
        r = measure(n, args.robots, args.episodes, args.scenario, args.repeats)
        print(
            f"{n:>6} {n + args.robots:>6} {r['steps']:>6} {r['median_ms']:>10.3f} {r['p95_ms']:>8.3f} "
            f"{r['mean_ms']:>8.3f} {r['orca_median_ms']:>13.3f} {100 * r['lp3_share']:>12.0f}%"
        )


if __name__ == "__main__":
    raise SystemExit(run_main(main))
