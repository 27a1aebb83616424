"""Exact coupling (the network inside the joint NLP) against its first-order fixed point.

The coupling experiment (docs/results.md, "Coupling") gives the exact coupled NLP 5 % success: IPOPT with
L-BFGS (the network stays an MX call node, mpc/coupled.py) hits its iteration or time limit on most steps and
the robots brake. This asks whether a better start would rescue it. It runs closed-loop CMPC episodes with
first-order coupling (the predictor linearised at the plan, re-linearised until F settles; its fixed point is
a stationary point of the exact problem, mpc/coupled.py) and, at every solved step, solves the exact NLP warm
from the first-order plan, outside the loop. Printed: the first-order episodes' success and collision rates (a
collision: some robot within d_min of a human at some step; the episode goes on, so an episode can count as
both), the exact solves' statuses, solver iterations and time, and how much lower the exact solve's F is than
the first-order plan's true F (the predictor itself, not its linearisation). A network's exact NLP is solved
by IPOPT alone (L-BFGS); a predictor small enough to expand into the NLP (constant velocity) gets the fixed-
prediction NLPs' solvers, Fatrop first and IPOPT where it fails: the iterations are then both solvers'
together, and which solver ran is printed. The machine is shared: the load is printed.

    nice -n 5 .venv/bin/python benchmarks/exact_coupling.py                      # 4 episodes, 7 humans
    nice -n 5 .venv/bin/python benchmarks/exact_coupling.py --episodes 10 --max-iter 30
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from crowdsim.env import CrowdEnv
from crowdsim.metrics import aggregate, episode_metrics
from mpc.coupled import CoupledCMPC
from mpc.solvers import SOLVED
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.mpc import MPCController
from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    count_in,
    episode_count,
    human_count,
    json_on_stdout,
    output_file,
    predictor_name,
    run_main,
    write_json,
)

PREDICTOR = "social_lstm_soft_eth"  # the coupling experiment's (pipelines/experiments)
# What runs an exact solve (JointNLP.first_solver), and whose iterations it counts: a network's NLP has IPOPT
# alone; an expanded one (constant velocity) Fatrop, then IPOPT where Fatrop failed, their counts added.
SOLVERS = {"ipopt": "IPOPT", "fatrop": "Fatrop, IPOPT where it failed"}
ITERATIONS = {"ipopt": "IPOPT", "fatrop": "Fatrop (+ IPOPT where it failed)"}
SOLVER_NAMES = {"ipopt": "IPOPT", "fatrop": "Fatrop"}


def measure(predictor: str, n_humans: int, episodes: int, max_iter: int) -> dict[str, Any]:
    spec = ControllerSpec("cmpc", predictor, coupling="nlp", mpc_overrides=(("coupled_mode", "first_order"),))
    controller = MPCController(spec, distributed=False)
    env = CrowdEnv()
    obs = env.reset(0, "circle", n_humans, 3)
    controller.reset(obs)
    first_order = controller.solver(3, n_humans)
    assert isinstance(first_order, CoupledCMPC)
    cfg = controller.cfg.replace(coupled_mode="exact", solver_max_iter=max_iter)
    exact = CoupledCMPC(cfg, 3, n_humans, first_order.function, controller.model.context_size(n_humans, 3))
    solve = first_order.solve
    # (status, iterations, the solver whose point it is, seconds, F first-order - F exact)
    rows: list[tuple[str, int, str, float, float]] = []

    def both(data, context, start):
        result = solve(data, context, start)
        if result.solved:
            t0 = time.perf_counter()
            sol = exact.nlp.solve(data, np.asarray(context, dtype=float), result.accels)
            seconds = time.perf_counter() - t0
            gain = result.potentials[-1] - sol.cost if sol.success else float("nan")
            rows.append((sol.status, sol.iterations, sol.solver, seconds, gain))
        return result

    first_order.solve = both  # type: ignore[method-assign]
    metrics = []
    for k in range(episodes):
        obs = env.reset(k // 2, ("circle", "perpendicular")[k % 2], n_humans, 3)
        controller.reset(obs)
        done = False
        while not done:
            obs, done, _ = env.step(controller.act(obs).accelerations)
        metrics.append(episode_metrics(env.trajectory()))
    controller.close()
    statuses = [r[0] for r in rows]
    iterations = np.array([r[1] for r in rows], dtype=float)
    solvers = [r[2] for r in rows]
    seconds = np.array([r[3] for r in rows])
    gains = np.array([r[4] for r in rows if r[0] in SOLVED])
    agg = aggregate(metrics)
    return {
        "predictor": predictor,
        "humans": n_humans,
        "episodes": episodes,
        "first_order_success_rate": agg["success_rate"],
        "first_order_collision_rate": agg["collision_rate"],
        "exact_max_iter": max_iter,
        "steps": len(rows),
        "statuses": {s: statuses.count(s) for s in sorted(set(statuses))},
        "exact_solver": exact.nlp.first_solver,
        "returned_by": {s: solvers.count(s) for s in sorted(set(solvers))},
        "exact_iterations_median": float(np.median(iterations)) if rows else float("nan"),
        "exact_iterations_p90": float(np.percentile(iterations, 90)) if rows else float("nan"),
        "exact_ms_median": 1e3 * float(np.median(seconds)) if rows else float("nan"),
        "exact_ms_p95": 1e3 * float(np.percentile(seconds, 95)) if rows else float("nan"),
        "F_gain_median": float(np.median(gains)) if gains.size else float("nan"),
        "F_gain_max": float(gains.max()) if gains.size else float("nan"),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--predictor", type=predictor_name, default=PREDICTOR)
    parser.add_argument("--humans", type=human_count, default=7)
    parser.add_argument("--episodes", type=episode_count, default=4)
    parser.add_argument(
        "--max-iter",
        type=count_in("max iter", 1),
        default=100,
        help="the exact solve's iteration limit (IPOPT's, and Fatrop's where it runs first)",
    )
    parser.add_argument("--json", type=output_file, help="also write the figures to this file")
    args = parser.parse_args(argv)
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        load = os.getloadavg()[0]
        row = measure(args.predictor, args.humans, args.episodes, args.max_iter)
        row["load_before"], row["load_after"] = load, os.getloadavg()[0]
        print(
            f"{row['predictor']}, {counted(row['humans'], 'human')}, "
            f"{counted(row['episodes'], 'episode')} of first-order coupling "
            f"(success {row['first_order_success_rate']:.0f} %, "
            f"collision {row['first_order_collision_rate']:.0f} %), "
            f"load {row['load_before']:.2f} -> {row['load_after']:.2f}"
        )
        print(
            f"exact solves from the first-order plan ({row['steps']} steps, max_iter {args.max_iter}, "
            f"{SOLVERS[row['exact_solver']]}):"
        )
        for status, count in row["statuses"].items():
            print(f"  {status:<32} {count:5d}")
        # No step, or no exact solve that succeeded, leaves a figure unmeasured (NaN): said in words, not
        # "nan".
        if row["steps"]:
            iterated = ITERATIONS[row["exact_solver"]]
            print(
                f"  {iterated} iterations median {row['exact_iterations_median']:.1f}, p90 "
                f"{row['exact_iterations_p90']:.1f}; time median {row['exact_ms_median']:.0f} ms, p95 "
                f"{row['exact_ms_p95']:.0f} ms"
            )
            if row["exact_solver"] == "fatrop":  # which solver's point each solve returned
                by = ", ".join(f"{SOLVER_NAMES[s]} {n}" for s, n in row["returned_by"].items())
                print(f"  the point returned by: {by}")
        else:
            print("  none solved: the first-order solve never succeeded, so no exact solve was started")
        gains = (
            f"median {row['F_gain_median']:.2e}, max {row['F_gain_max']:.2e}"
            if math.isfinite(row["F_gain_median"])
            else f"none solved (the exact solve succeeded on none of the {row['steps']} steps)"
        )
        print(f"  F(first-order plan) - F(exact solution), solved steps: {gains}")
        if args.json:
            write_json(args.json, row)
        return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
