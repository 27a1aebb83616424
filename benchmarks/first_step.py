"""Why a step that starts from braking asks both solvers (mpc/solvers.py, ``_Solver``): CMPC episodes three
ways on the same seeds, with the default solver (Fatrop, and on such a step IPOPT too, the lower cost kept),
with IPOPT alone (``solver = "ipopt"``), and with Fatrop alone (that exploration turned off: every solve goes
to Fatrop, and to IPOPT only when Fatrop fails). From rest the first step's NLP has several local minima,
and the one it picks sets the team's formation for the episode; this prints what each choice does to the
episodes: success, collision (closer than 0.8 m), contact and mean travel time, and in how many episodes
the first step took the robots elsewhere than the default did.

    nice -n 5 .venv/bin/python benchmarks/first_step.py        # 40 episodes, social_lstm_eth, 7 humans
    nice -n 5 .venv/bin/python benchmarks/first_step.py --predictor constant_velocity --scenario perpendicular
    nice -n 5 .venv/bin/python benchmarks/first_step.py --profile v1
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    episode_count,
    human_count,
    json_on_stdout,
    output_file,
    predictor_name,
    run_main,
    seed_number,
    write_json,
)

MODES = ("default", "ipopt_alone", "fatrop_alone")


@contextmanager
def fatrop_alone() -> Iterator[None]:
    """Every ``_Solver.solve`` without the exploration of a step from braking (restored on leaving)."""
    from mpc import solvers

    original = solvers._Solver.solve

    def without_exploring(self, x0, p, lbx, ubx, lbg, ubg, lam_x0=None, lam_g0=None, explore=False):
        return original(self, x0, p, lbx, ubx, lbg, ubg, lam_x0, lam_g0, False)

    solvers._Solver.solve = without_exploring  # type: ignore[method-assign]
    try:
        yield
    finally:
        solvers._Solver.solve = original  # type: ignore[method-assign]


def run_mode(mode: str, args: argparse.Namespace) -> list[Any]:
    """The episodes of one ``mode`` (``MODES``)."""
    from crowdsim.profiles import make_env_config
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.episode import run_episodes

    overrides = (("solver", "ipopt"),) if mode == "ipopt_alone" else ()
    spec = ControllerSpec("cmpc", args.predictor, mpc_overrides=overrides)

    def run() -> list[Any]:
        return run_episodes(
            spec,
            episodes=args.episodes,
            seed=args.seed,
            scenario=args.scenario,
            n_humans=args.humans,
            progress=True,
            env_config=make_env_config(args.profile, "visible"),
        )

    if mode != "fatrop_alone":
        return run()
    with fatrop_alone():
        return run()


def summary(results: list[Any]) -> dict[str, float]:
    """Success, collision and contact (% of episodes) and the mean travel time (s) of the successes."""
    travel = [r.metrics.travel_time for r in results if r.metrics.success]
    return {
        "success_pct": 100.0 * np.mean([r.metrics.success for r in results]),
        "collision_pct": 100.0 * np.mean([r.metrics.collision for r in results]),
        "contact_pct": 100.0 * np.mean([r.metrics.contact for r in results]),
        "travel_time_s": float(np.mean(travel)) if travel else float("nan"),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--predictor", type=predictor_name, default="social_lstm_eth")
    parser.add_argument("--episodes", type=episode_count, default=40)
    parser.add_argument("--humans", type=human_count, default=7)
    parser.add_argument("--scenario", choices=("circle", "perpendicular"), default="circle")
    parser.add_argument("--seed", type=seed_number, default=0)
    parser.add_argument(
        "--profile", choices=("paper", "v1"), default="paper", help="the simulator's conventions"
    )
    parser.add_argument("--json", type=output_file, default=None, metavar="FILE")
    args = parser.parse_args()
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        _measure(args)


def _measure(args: argparse.Namespace) -> None:
    runs = {mode: run_mode(mode, args) for mode in MODES}
    default_paths = [r.robot_positions[1] for r in runs["default"]]
    # what the header line names, so that a saved file says what it measured
    report: dict[str, Any] = {
        "predictor": args.predictor,
        "episodes": args.episodes,
        "humans": args.humans,
        "scenario": args.scenario,
        "seed": args.seed,
        "profile": args.profile,
        "modes": {},
    }
    print(
        f"CMPC, {args.predictor}, {counted(args.humans, 'human')}, {args.scenario}, {args.profile}, "
        f"seeds {args.seed}.."
        f"{args.seed + args.episodes - 1}: success / collision / contact %, travel s; first step elsewhere"
    )
    for mode, results in runs.items():
        # the first step's robot positions: where the NLP's local minimum took the team
        moved = sum(
            not np.allclose(r.robot_positions[1], d, atol=1e-6)
            for r, d in zip(results, default_paths, strict=True)
        )
        figures = summary(results) | {"first_step_elsewhere": moved}
        report["modes"][mode] = figures
        print(
            f"  {mode:13s} {figures['success_pct']:5.1f} / {figures['collision_pct']:5.1f} / "
            f"{figures['contact_pct']:5.1f}, {figures['travel_time_s']:.2f} s; first step elsewhere in "
            f"{moved} of {len(results)}"
        )
    if args.json is not None:
        write_json(args.json, report)


if __name__ == "__main__":
    sys.exit(run_main(main))
