"""What ``MPCController.prepare`` costs before a real robot's loop: the seconds each number of humans takes.

On a robot the number of humans changes as people come and go, and a step meeting a size the controller has
not built builds its NLP, solvers, predictor twin and encoder inside itself (docs/extending.md, section 7).
``prepare(robots, humans)`` builds them first. This prints the seconds per size, without jit, or with
``--jit`` twice: on a private, empty compile cache (what a robot's first start pays) and then from it, in a
second controller (every later start). The user's cache is not touched. The load average is printed with
each run: the machine is shared. With each run, the resident memory (``VmRSS``) the sizes added: the
controller keeps every size it built for as long as it lives (a loop that varies the crowd holds one per size
met), and gives it back when dropped, to the process's allocator (``rss_mb`` is None without /proc).

    nice -n 5 .venv/bin/python benchmarks/prepare.py                          # CMPC, 0..15 humans, no jit
    nice -n 5 .venv/bin/python benchmarks/prepare.py --jit --humans 5 7 9
    nice -n 5 .venv/bin/python benchmarks/prepare.py --controller dmpc --predictor constant_velocity --json -
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    human_count,
    json_on_stdout,
    output_file,
    predictor_name,
    private_cache,
    robot_count,
    run_main,
    write_json,
)


def resident_mb() -> float | None:
    """This process's resident memory now (``VmRSS``), MB; None without /proc (macOS)."""
    try:
        with open("/proc/self/status", encoding="utf-8") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None


def prepare_once(controller: str, predictor: str, robots: int, humans: list[int], jit: bool) -> dict:
    """A new controller's ``prepare`` of every size, timed; the load average around it; the resident memory
    the sizes added (``rss_mb``): what the controller holds while it lives."""
    from pipelines.loop.controllers import ControllerSpec, make_controller

    built = make_controller(ControllerSpec(controller, predictor), jit=jit)
    load_before, rss_before, t0 = os.getloadavg()[0], resident_mb(), time.perf_counter()
    seconds = built.prepare(robots, humans)  # type: ignore[attr-defined]  # MPCController's
    total = time.perf_counter() - t0
    rss_after = resident_mb()
    built.close()
    return {
        "seconds": {str(n): s for (_, n), s in seconds.items()},
        "total_s": total,
        "load": [load_before, os.getloadavg()[0]],
        "rss_mb": None if rss_before is None or rss_after is None else rss_after - rss_before,
    }


def print_run(label: str, run: dict) -> None:
    sizes = run["seconds"]
    held = "" if run["rss_mb"] is None else f", {run['rss_mb']:+.0f} MB resident"
    built = counted(len(sizes), "size")
    load = f"(load {run['load'][0]:.2f} -> {run['load'][1]:.2f})"
    print(f"{label}: {run['total_s']:.2f} s for {built}{held} {load}")
    print("  humans  " + " ".join(f"{n:>6}" for n in sizes))
    print("  s       " + " ".join(f"{s:>6.2f}" for s in sizes.values()))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--controller", choices=("cmpc", "dmpc"), default="cmpc")
    parser.add_argument("--predictor", type=predictor_name, default="social_lstm_eth")
    parser.add_argument("--robots", type=robot_count, default=3)
    parser.add_argument("--humans", type=human_count, nargs="+", default=list(range(16)))
    parser.add_argument("--jit", action="store_true", help="compile: a cold cache, then a warm one")
    parser.add_argument("--json", type=output_file, help="write the figures to this file ('-': stdout)")
    args = parser.parse_args()
    humans = list(dict.fromkeys(args.humans))  # each size once, in the order given
    with json_on_stdout(args.json):
        print(
            f"{args.controller}, {args.predictor}, {counted(args.robots, 'robot')}, "
            f"jit {'on' if args.jit else 'off'}"
        )
        runs = {}
        if not args.jit:
            runs["no_jit"] = prepare_once(args.controller, args.predictor, args.robots, humans, False)
        else:
            with private_cache("crowdmpc-prepare-"):  # empty: the first controller compiles every size
                for label in ("cold_cache", "warm_cache"):
                    runs[label] = prepare_once(args.controller, args.predictor, args.robots, humans, True)
        for label, run in runs.items():
            print_run(label.replace("_", " "), run)
    if args.json:
        payload = {"controller": args.controller, "predictor": args.predictor, "robots": args.robots, **runs}
        write_json(args.json, payload)


if __name__ == "__main__":
    raise SystemExit(run_main(main))
