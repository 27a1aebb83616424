"""Time of one MPC control step in closed loop, and the floor: one bare solve of the same joint NLP.

For each crowd size, seeded circle-crossing episodes are run with the controller through CrowdEnv (3 robots)
and every control step's wall time is taken from ``ControlOutput.solve_time_s`` (predictions, every solve,
the IBR bookkeeping). Rows:

* ``cmpc`` / ``dmpc``: Algorithms 1 and 2 with the constant-velocity predictor (or ``--predictor``);
* ``floor``: the joint NLP of the CMPC rows solved once with the prediction fixed, from the same warm start
  as CMPC's first solve, for every recorded step: what the solver alone costs (no predictor, no IBR);
* ``--dmpc-parallel``: DMPC with its local solves one after the other and in a thread pool;
* ``--coupled``: CMPC with the predictor inside the NLP (``coupling="nlp"``), exact and first-order.

Medians and 95th percentiles in milliseconds. The machine is shared: the load average is printed; run it
under ``nice`` and repeat when the figures look noisy.

    nice -n 10 .venv/bin/python benchmarks/control_step.py
    nice -n 10 .venv/bin/python benchmarks/control_step.py --humans 7 --episodes 4 --dmpc-parallel --coupled
    nice -n 10 .venv/bin/python benchmarks/control_step.py --humans 7 --coupled --predictor social_lstm_eth
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from crowdsim.env import CrowdEnv
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.mpc import MPCController
from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    check_distinct,
    episode_count,
    human_count,
    json_on_stdout,
    output_file,
    predictor_name,
    run_main,
    write_json,
)


def _stats(seconds: list[float]) -> dict[str, float]:
    ms = np.asarray(seconds, dtype=float) * 1e3
    return {"median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95)), "steps": int(ms.size)}


def closed_loop(spec: ControllerSpec, n_humans: int, episodes: int, floor: bool = False) -> dict[str, Any]:
    """Step times of ``spec`` over ``episodes`` circle episodes (seeds 0..), and optionally the floor."""
    controller = MPCController(spec, distributed=spec.controller == "dmpc")
    env = CrowdEnv()
    records: list[tuple] = []
    if floor:
        cmpc = controller.solver(3, n_humans)
        solve = cmpc.solve

        def recording(data, predict, start):
            result = solve(data, predict, start)
            if result.predictions:
                records.append((data, start, result.predictions[0]))
            return result

        cmpc.solve = recording
    times, iterations, solves = [], [], []
    for seed in range(episodes):
        obs = env.reset(seed, "circle", n_humans, 3)
        controller.reset(obs)
        done = False
        while not done:
            out = controller.act(obs)
            times.append(out.solve_time_s)
            iterations.append(out.iterations)
            solves.append(out.extra.get("solves", 0))
            obs, done, _ = env.step(out.accelerations)
    row = _stats(times) | {
        "iterations_mean": float(np.mean(iterations)),
        "solves_mean": float(np.mean(solves)),
    }
    if floor:
        nlp = controller.solver(3, n_humans).nlp
        bare = []
        for data, start, prediction in records:
            t0 = time.perf_counter()
            nlp.solve(data, prediction, start.accels, start.lam_x, start.lam_g)
            bare.append(time.perf_counter() - t0)
        row["floor"] = _stats(bare)
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--humans", type=human_count, nargs="+", default=[5, 7, 9])
    parser.add_argument(
        "--episodes", type=episode_count, default=3, help="circle episodes per row (seeds 0..)"
    )
    parser.add_argument("--predictor", type=predictor_name, default="constant_velocity")
    parser.add_argument("--dmpc-parallel", action="store_true", help="DMPC serial vs thread pool (7 humans)")
    parser.add_argument(
        "--coupled", action="store_true", help="CMPC with coupling='nlp' (exact, first_order)"
    )
    parser.add_argument("--no-ibr", action="store_true", help="skip the CMPC/DMPC/floor rows")
    parser.add_argument("--json", type=output_file, help="also write the figures to this file")
    args = parser.parse_args(argv)
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        check_distinct(parser, "--humans", args.humans)  # the JSON's rows are keyed by it
        if args.no_ibr and not args.coupled and not (args.dmpc_parallel and 7 in args.humans):
            parser.error(
                "nothing to measure: --no-ibr leaves --coupled and --dmpc-parallel (which runs at 7 humans)"
            )
        if args.dmpc_parallel and 7 not in args.humans:  # it measured nothing, and said nothing
            parser.error("--dmpc-parallel runs at 7 humans: add 7 to --humans")

        report: dict[str, Any] = {"load_before": os.getloadavg()}
        rows: list[tuple[str, int, dict[str, Any]]] = []  # (kind, padded as printed; humans; row)
        for n in args.humans:
            if not args.no_ibr:
                cmpc = closed_loop(ControllerSpec("cmpc", args.predictor), n, args.episodes, floor=True)
                # the ratio of the two medians (not a median of per-step ratios), printed under the
                # floor's row
                cmpc["median_over_floor_median"] = cmpc["median_ms"] / cmpc["floor"]["median_ms"]
                rows.append(("cmpc     ", n, cmpc))
                rows.append(("floor    ", n, cmpc["floor"]))
                rows.append(
                    ("dmpc     ", n, closed_loop(ControllerSpec("dmpc", args.predictor), n, args.episodes))
                )
            if args.dmpc_parallel and n == 7:
                for mode in ("serial", "threads"):
                    spec = ControllerSpec("dmpc", args.predictor, mpc_overrides=(("dmpc_parallel", mode),))
                    rows.append((f"dmpc {mode:<7}", n, closed_loop(spec, n, args.episodes)))
            if args.coupled:
                for mode in ("exact", "first_order"):
                    spec = ControllerSpec(
                        "cmpc", args.predictor, coupling="nlp", mpc_overrides=(("coupled_mode", mode),)
                    )
                    rows.append((f"nlp {mode:<11}", n, closed_loop(spec, n, args.episodes)))
        report["load_after"] = os.getloadavg()
        report["predictor"] = args.predictor
        # the JSON's keys say "N humans" whatever N, as docs/outputs.md documents them; the table counts
        report["rows"] = {f"{kind} {n} humans": row for kind, n, row in rows}

        episodes = counted(args.episodes, "episode")
        print(f"predictor {args.predictor}, 3 robots, circle crossing, {episodes} per row")
        print(f"load average before {report['load_before'][0]:.2f}, after {report['load_after'][0]:.2f}")
        print(f"{'row':<30} {'median ms':>10} {'p95 ms':>10} {'steps':>6} {'IBR its':>8} {'solves':>7}")
        cmpc_row: dict[str, Any] = {}
        for kind, n, row in rows:
            label = f"{kind} {counted(n, 'human')}"
            its = f"{row['iterations_mean']:8.2f}" if "iterations_mean" in row else " " * 8
            sol = f"{row['solves_mean']:7.2f}" if "solves_mean" in row else " " * 7
            print(f"{label:<30} {row['median_ms']:10.2f} {row['p95_ms']:10.2f} {row['steps']:6d} {its} {sol}")
            if label.startswith("cmpc"):
                cmpc_row = row
            if label.startswith("floor"):  # the row after its CMPC row
                print(f"{'  median cmpc / median floor':<30} {cmpc_row['median_over_floor_median']:10.2f}")
        if args.json:
            write_json(args.json, report)
        return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
