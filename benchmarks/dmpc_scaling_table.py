"""benchmarks/dmpc_scaling.py's report as a table: each cell's serial and threaded rows, then the speed-up
line with the trajectories' and the replayed solves' comparison."""

from __future__ import annotations

import argparse
from typing import Any

from predictors.text_table import counted


def print_report(
    report: dict[str, Any], args: argparse.Namespace, predictor: str, extra: tuple[tuple[str, Any], ...]
) -> None:
    """The table of ``report`` (one row per cell and mode, a speed-up line under each threaded cell)."""
    print(
        f"DMPC, {predictor}, circle crossing, {counted(args.humans, 'human')}, "
        f"{counted(args.episodes, 'episode')} per row, "
        f"{report['cpus']} CPUs" + "".join(f", {k}={v}" for k, v in extra)
    )
    print(
        f"load average before {report['load_before'][0]:.2f}, after {report['load_after'][0]:.2f}; "
        f"{report['wall_s']:.0f} s"
    )
    header = (
        f"{'M':>2} {'update:stop':<32} {'solves':<8} {'median':>7} {'p95':>7} {'p99':>7} {'IBR its':>7} "
        f"{'j_max':>6} {'solves':>6} {'phase':>7} {'succ':>5} {'coll':>5} {'tout':>5}"
    )
    print(header)
    print(
        f"{'':>2} {'':<32} {'':<8} {'ms':>7} {'ms':>7} {'ms':>7} {'/step':>7} {'%':>6} {'/step':>6} {'ms':>7}"
    )
    for key, cell in report["cells"].items():
        m, rule = key[1:].split(" ", 1)
        for mode, row in cell["rows"].items():
            print(
                f"{m:>2} {rule:<32} {mode:<8} {row['median_ms']:7.1f} {row['p95_ms']:7.1f} "
                f"{row['p99_ms']:7.1f} {row['iterations_mean']:7.2f} {100 * row['at_j_max']:6.0f} "
                f"{row['solves_per_step']:6.1f} {row['phase_ms_per_step']:7.1f} "
                f"{row['success']:>2}/{row['episodes']:<2} {row['collision']:>2}/{row['episodes']:<2} "
                f"{row['timeout']:>2}/{row['episodes']:<2}"
            )
        if "speedup" in cell:
            speedup = cell["speedup"]
            line = (
                f"{'':>2} {'':<32} speed-up (serial / threads): step median x{speedup['step_median']:.2f}, "
                f"phase x{speedup['phase']:.2f}, same trajectories: {cell['same']}"
            )
            if cell["cut"]:
                of = counted(args.episodes, "episode")
                line += f" (in {cell['cut']} of {of} up to a step past the time limit)"
            if "replay" in cell:
                rp = cell["replay"]
                cut = f", {rp['cut']} solves past the time limit not compared" if rp["cut"] else ""
                line += (
                    f"; replayed phase {rp['serial_ms']:.2f} -> {rp['threads_ms']:.2f} ms/iteration "
                    f"(x{rp['speedup']:.2f}, bitwise equal: {rp['identical']}{cut}); with no "
                    f"overhead at most x{rp['bound_in_order']:.2f} in order, "
                    f"x{rp['bound_longest_first']:.2f} longest first"
                )
            print(line)
