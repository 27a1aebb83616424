"""Fatrop's failures and iterations against ``MPCConfig.cost_scale``, on the NLPs the closed loop solves.

IPOPT scales the NLP by its gradients; Fatrop does not, and the 1e7 collision weight (Table I) leaves the
joint NLP badly scaled once several penalties are active: a Fatrop solve that runs to ``solver_max_iter`` is
retried with IPOPT (mpc/solvers.py), which costs the failed attempt and a solve that is 3-6x slower. For each
``--cost-scale`` this runs the same CMPC episodes (constant velocity, ``--config`` settings, episode ``i``:
seed ``i``, circle for even ``i``, perpendicular for odd) and reads every Fatrop call's statistics: solves,
failures, iterations of the successful ones, and the step time. The machine is shared: compare the scales
in one run, and read the ratios.

    nice -n 5 .venv/bin/python benchmarks/cost_scale.py --robots 3 12 --episodes 4
    nice -n 5 .venv/bin/python benchmarks/cost_scale.py --config docs/examples/safe_crossing.toml
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

from mpc import solvers
from pipelines.config import RunConfig, load
from pipelines.errors import PipelineError
from pipelines.loop.margins import parse_margins
from predictors.text_table import counted

# robot_scaling.py, the episodes' runner, is imported by name however this is run.
sys.path.insert(0, str(Path(__file__).resolve().parent))
import robot_scaling  # noqa: E402
from bench_cli import (  # noqa: E402
    check_distinct,
    check_not_input,
    episode_count,
    figure,
    human_count,
    json_on_stdout,
    output_file,
    predictor_name,
    robot_count,
    run_main,
    write_json,
)


def measure(run: RunConfig, n_robots: int, n_humans: int, episodes: int, predictor: str) -> dict[str, Any]:
    """The CMPC episodes of one row under ``run``, whose ``mpc.cost_scale`` is the row's scale."""
    margins = parse_margins(run.controller.margins or "none")
    # A solve's info describes the solver whose result was kept (IPOPT after a Fatrop failure), so Fatrop's
    # own statistics are read around every call instead.
    calls: list[tuple[int, bool]] = []  # (Fatrop iterations, success)
    solve = solvers._Solver.solve

    def recorded(self, *args, **kwargs):
        out = solve(self, *args, **kwargs)
        if self._fatrop is not None:
            stats = self._fatrop.stats()
            calls.append((int(stats["iter_count"]), bool(stats["success"])))
        return out

    solvers._Solver.solve = recorded  # type: ignore[method-assign]
    try:  # episode i: seed i, circle for even i, perpendicular for odd, the robots in their formation
        row = robot_scaling.run_row(
            "cmpc",
            predictor,
            n_robots,
            n_humans,
            episodes,
            0,
            robot_scaling.SCENARIOS,
            "auto",
            run.mpc_overrides(),
            margins,
        )
    finally:
        solvers._Solver.solve = solve  # type: ignore[method-assign]
    iterations = np.array([c[0] for c in calls])
    ok = np.array([c[1] for c in calls], dtype=bool)
    return {
        "cost_scale": run.mpc.cost_scale,
        "robots": n_robots,
        "fatrop_solves": len(calls),
        "fatrop_failed": int((~ok).sum()),
        "iterations_median": float(np.median(iterations[ok])) if ok.any() else float("nan"),
        "iterations_p90": float(np.percentile(iterations[ok], 90)) if ok.any() else float("nan"),
        "step_median_ms": row["median_ms"],
        "step_p95_ms": row["p95_ms"],
        "step_p99_ms": row["p99_ms"],
        "success_rate": row["success_rate"],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--config", help="a crowdmpc config file ([mpc] and [controller] margins)")
    parser.add_argument("--cost-scale", type=float, nargs="+", default=[1.0, 0.01])
    parser.add_argument("--robots", type=robot_count, nargs="+", default=[3, 12])
    parser.add_argument("--humans", type=human_count, default=7)
    parser.add_argument("--episodes", type=episode_count, default=4)
    parser.add_argument("--predictor", type=predictor_name, default="constant_velocity")
    parser.add_argument("--json", type=output_file, help="also write the rows to this file")
    args = parser.parse_args(argv)
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        check_not_input(parser, "--json", args.json, [args.config])
        for option in ("cost_scale", "robots"):  # a repeat ran its rows twice
            check_distinct(parser, f"--{option.replace('_', '-')}", getattr(args, option))
        try:  # every scale's config checked before the first episode
            runs = {scale: load(args.config, sets=[f"mpc.cost_scale={scale}"]) for scale in args.cost_scale}
        except PipelineError as exc:  # ConfigError, and what a value's own check raises
            parser.error(f"--config/--cost-scale: {exc}")
        load_before = os.getloadavg()[0]
        t0 = time.perf_counter()
        rows = [
            measure(runs[scale], m, args.humans, args.episodes, args.predictor)
            for m in args.robots
            for scale in args.cost_scale
        ]
        print(
            f"CMPC, {args.predictor}, {counted(args.humans, 'human')}, "
            f"{counted(args.episodes, 'episode')} a row, config "
            f"{args.config or 'none (the paper)'}; load {load_before:.2f} -> {os.getloadavg()[0]:.2f}, "
            f"{time.perf_counter() - t0:.0f} s"
        )
        print(f"{'M':>3} {'scale':>6} {'solves':>6} {'failed':>6} {'fail%':>6} {'it med':>6} {'it p90':>6} "
              f"{'med ms':>7} {'p95 ms':>7} {'p99 ms':>7} {'succ%':>6}")  # fmt: skip
        for r in rows:
            failed = 100 * r["fatrop_failed"] / r["fatrop_solves"] if r["fatrop_solves"] else math.nan
            print(
                f"{r['robots']:>3} {r['cost_scale']:>6g} {r['fatrop_solves']:>6} {r['fatrop_failed']:>6} "
                f"{figure(failed, '>6.1f')} {figure(r['iterations_median'], '>6.1f')} "
                f"{figure(r['iterations_p90'], '>6.1f')} {r['step_median_ms']:>7.1f} "
                f"{r['step_p95_ms']:>7.1f} {r['step_p99_ms']:>7.1f} {r['success_rate']:>6.1f}"
            )
        if any(not math.isfinite(r["iterations_median"]) for r in rows):  # the config's solver is not Fatrop
            print("-: none solved by Fatrop in that row (no Fatrop solve, or every one failed)")
        if args.json:
            write_json(args.json, {"args": vars(args), "rows": rows})
        return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
