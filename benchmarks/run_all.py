"""Every speed figure of the project in one run: a table, then the same numbers as JSON.

    nice -n 10 .venv/bin/python benchmarks/run_all.py            # everything (several minutes on 2 cores)
    nice -n 10 .venv/bin/python benchmarks/run_all.py --quick    # fewer sizes, shorter runs
    nice -n 10 .venv/bin/python benchmarks/run_all.py --json out.json --sections simulator,control

Sections
  simulator   one CrowdEnv.step (ORCA for every human + the robots' integration), humans 5..50, robots 3..12
              (benchmarks/orca_step.py's ``measure``)
  control     one control step (ControlOutput.solve_time_s: prediction + every solve) per controller, CMPC's
              floor (the joint NLP solved once with the prediction fixed), and CMPC per predictor (every one
              the registry has, the ORCA oracle among them) and per coupling (benchmarks/control_step.py's
              ``closed_loop`` for CMPC/DMPC, whole circle-crossing episodes)
  scaling     CMPC and DMPC control step against the number of humans (5..50, control_step.py) and of robots
              (3..12, here: control_step.py has 3 robots)
  dmpc        DMPC's local solves in a thread pool vs one after the other (mpc/dmpc.py): the speed-up
  episodes    episodes per minute of one process per controller (Table II's predictor, 7 humans), and of a
              real Table II sweep (5-9 humans) with K workers, with the projected time of the paper's full
              Table II (10 cells x 1000 episodes) from its rate and from its CPU time per episode; and
              the share of a Table II episode spent inside CasADi, with the table's time if the Python
              around it took none (benchmarks/sweep_floor.py; quick: 2 timed episodes a cell)
  export      the exported CasADi predictors against the hand-written twins (Social-LSTM family): export
              time, parity with torch (values, Jacobians), the IBR prediction call and the coupled-NLP control
              step over one circle episode (benchmarks/export.py's ``measure``; quick: one model, no episode)
  robots      CMPC and DMPC control step in whole paper-profile episodes with M robots in their formations
              (3..12, ``auto``), with success rate and fallbacks, as the paper and with the many-robot
              settings (docs/examples/many_robots.toml), and with those settings on the goal-slots task
              (``slots``: crowdsim/slots.py; benchmarks/robot_scaling.py's ``run_row``; quick: CMPC at 3 and
              6 robots, 1 episode)
  dmpc_updates  DMPC's update rules (UPDATE:STOP) x local solves serial/threads, circle episodes, 3..12 robots
              (benchmarks/dmpc_scaling.py's ``closed_loop``; quick: 3 and 6 robots, jacobi:regret and
              sequential_accept:no_improvement, 1 episode)
  ibr         CMPC's step against its floor, jit off and on (social_lstm_eth, 7 humans): the first solve (the
              floor), the later IBR solves, the predictor and the rest (benchmarks/ibr_solves.py; quick: 1
              episode)

What is compiled (the episodes' sections, ibr's jit on) goes to a private compile cache, empty at the start,
removed at the end and shared by the sections: the user's cache is neither filled nor read, so a cell's
first episodes pay the compile on every run, as on a fresh machine.

Rows measured here rather than by control_step.py (the baselines, the oracle, robots != 3) time the first
``--steps`` control steps of episodes of both scenarios (export, robots and dmpc_updates time whole episodes).
Medians and 95th percentiles in milliseconds. The machine is shared: figures vary with the load, which is
printed.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path
from typing import Any

import numpy as np

# The sibling benchmark modules (orca_step.py, control_step.py, export.py, robot_scaling.py, dmpc_scaling.py)
# and this script's parts (run_all_parts/) are imported by name, however this is run.
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_cli import (  # noqa: E402
    count_in,
    is_stdout,
    json_on_stdout,
    json_text,
    output_file,
    private_cache,
    run_main,
    write_text,
)
from run_all_parts.sections import SECTION_RUNS, Run  # noqa: E402
from run_all_table import table  # noqa: E402

SECTIONS = ("simulator", "control", "scaling", "dmpc", "episodes", "export", "robots", "dmpc_updates", "ibr")
assert tuple(SECTION_RUNS) == SECTIONS


def run(args: argparse.Namespace) -> dict[str, Any]:
    quick = args.quick
    steps = args.steps or (8 if quick else 20)
    context = Run(quick, steps, args.workers, args.sweep_episodes, errors={})
    report: dict[str, Any] = {
        "machine": {
            "cpus": os.cpu_count(),
            "load_average": list(os.getloadavg()),
            "python": platform.python_version(),
            "platform": platform.platform(),
            "numpy": np.__version__,
        },
        "settings": {"steps": steps, "quick": quick, "workers": args.workers},
    }
    for name, (key, measure) in SECTION_RUNS.items():
        if name in args.sections:
            report[key] = measure(context)
    report["errors"] = context.errors
    return report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="fewer steps and sizes")
    parser.add_argument(
        "--steps", type=count_in("steps", 1), help="control steps timed per episode (default 20, quick 8)"
    )
    parser.add_argument(
        "--workers",
        type=count_in("workers", 1),
        default=2,
        help="workers of the sweep measurement (default 2)",
    )
    parser.add_argument("--sweep-episodes", type=int, help="episodes per cell of the sweep measurement")
    parser.add_argument(
        "--sections",
        type=lambda s: tuple(part.strip() for part in s.split(",")),
        default=SECTIONS,
        metavar="NAME,NAME,...",
        help=f"comma-separated, from: {', '.join(SECTIONS)}",
    )
    parser.add_argument("--json", type=output_file, help="also write the JSON here")
    args = parser.parse_args(argv)
    if args.sweep_episodes is not None and args.sweep_episodes < 2:
        parser.error(f"--sweep-episodes must be >= 2 (a worker's first episode of a cell is not timed), got "
                     f"{args.sweep_episodes}")  # fmt: skip
    unknown = set(args.sections) - set(SECTIONS)
    if unknown:
        parser.error(f"unknown sections {sorted(unknown)}; choose from {list(SECTIONS)}")
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        with private_cache("crowdmpc-run-all-cache-"):  # one for every section: each reuses what one compiled
            report = run(args)
        print(table(report))  # run_all_table.py
        text = json_text(report, indent=1)
        if not is_stdout(args.json):  # printed once, on stdout, by write_text
            print(text)
        if args.json:
            write_text(args.json, text)
        return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
