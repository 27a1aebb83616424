"""DMPC (Algorithm 2) against the number of robots: its update rules, and its local solves serial vs threaded.

For every number of robots M (``--robots``, default 3 6), DMPC rule (``--rules``: ``UPDATE:STOP`` pairs of
``MPCConfig.dmpc_update`` and ``dmpc_stop``, default ``RULES``: the paper's ``jacobi:regret`` and the
alternatives of mpc/dmpc.py) and way of running the local solves (``--parallel``, default ``serial`` and
``threads``; ``gauss_seidel`` solves one robot at a time and runs serially only), ``--episodes``
circle-crossing episodes (seeds 0.., ``CrowdEnv.reset(seed, "circle", humans, M)``) with ``--humans`` humans
(default 7) and the constant-velocity predictor. The parallel modes of one (M, rule) run each seed one after
the other, so that both see the same load; their trajectories must be identical (checked: "same"), up to
a step past ``MPCConfig.time_limit_s`` in either, after which the load decides ("cut": episodes so cut).

Per row: the control step (``ControlOutput.solve_time_s``) as median / p95 / p99 in ms over every step of
every episode; IBR iterations per step (mean) and the share of steps that ran to j_max; local solves per
step; the local-solve phase (``DMPC._solve_all``: every local solve of the step) in ms per step (mean); and
success / collision / timeout counts (a collision is an episode in which some robot came within d_min of a
human; it does not end the episode, so an episode can count as both a success and a collision). Then, per
(M, rule), the threads' speed-up (serial / threads: above 1, threads are faster) of the step median and of
the local-solve phase.

``--replay``: the local-solve phase alone, on the iterations recorded from one serial episode of each (M,
rule): every recorded batch of M local problems is solved by DMPC's serial and threaded code paths
alternately (the order flips each repetition), so that both see the same load, after one untimed pass; the
results are compared bit for bit, but for a problem whose solve ran past ``time_limit_s`` in either path
(the clock ended it: left out and counted, "cut"). Then every local problem is timed alone (the least of
``--replay-reps`` serial solves), and the batches' durations give the speed-up that ``cores()`` threads
could reach with no overhead at all: taking each batch's jobs in order, as ``mpc.parallel.run_in_threads``
does, and, for comparison, longest first with the durations known beforehand. The solves are uneven (a
Fatrop failure redone by IPOPT costs several ordinary solves), so even the first bound is well under the
thread count.

``--mpc KEY=VALUE`` sets any other [mpc] value for every row, as ``crowdmpc --set mpc.KEY=VALUE`` takes it
(the rows set ``dmpc_update``, ``dmpc_stop`` and ``dmpc_parallel`` themselves). ``--mpc cost_scale=0.01``
(docs/examples/many_robots.toml's value) makes the local solves more even, since Fatrop then rarely fails
and hands a problem to IPOPT: at 6 robots with Jacobi the bound rises from x1.69 to x1.80 and the
measured speed-up from x1.55 to x1.60 (docs/results.md, "DMPC's local solves in threads").

The machine is shared: the load average is printed before and after; run it under ``nice`` and read the
speed-ups together with the load (a parallel phase needs a free core to be faster).

    nice -n 5 .venv/bin/python benchmarks/dmpc_scaling.py --episodes 3 --robots 3 6
    nice -n 5 .venv/bin/python benchmarks/dmpc_scaling.py --episodes 1 --robots 6 --replay \\
        --rules sequential_accept:no_improvement
    nice -n 5 .venv/bin/python benchmarks/dmpc_scaling.py --episodes 2 --robots 6 12 --replay \\
        --rules jacobi:regret --mpc cost_scale=0.01
"""

from __future__ import annotations

import argparse
import heapq
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from mpc.config import DMPC_STOPS, DMPC_UPDATES, PARALLEL_MODES
from mpc.dmpc import DMPC
from mpc.solvers import Solution
from pipelines.commands.simulate_table import BUDGET_STATUSES
from pipelines.config import ConfigError, load
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.episode import run_episode
from pipelines.loop.mpc import MPCController

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    check_distinct,
    count_in,
    episode_bar,
    episode_count,
    human_count,
    json_on_stdout,
    mpc_sets,
    output_file,
    robot_count,
    run_main,
    write_json,
)
from dmpc_scaling_table import print_report  # noqa: E402

PREDICTOR = "constant_velocity"
Overrides = tuple[tuple[str, Any], ...]
# (dmpc_update, dmpc_stop): Algorithm 2 as printed, then the alternatives (mpc/dmpc.py has why these).
RULES: tuple[str, ...] = (
    "jacobi:regret",
    "gauss_seidel:regret",
    "gauss_seidel:no_improvement",
    "sequential_accept:no_improvement",
    "relaxed:no_improvement",
)


# What a row varies itself; ``--mpc`` sets anything else.
ROW_KEYS = frozenset({"dmpc_update", "dmpc_stop", "dmpc_parallel"})


def _controller(rule: str, parallel: str, extra: Overrides = ()) -> MPCController:
    update, stop = rule.split(":")
    overrides = (*extra, ("dmpc_update", update), ("dmpc_stop", stop), ("dmpc_parallel", parallel))
    return MPCController(ControllerSpec("dmpc", PREDICTOR, mpc_overrides=overrides), distributed=True)


def mpc_overrides(texts: Sequence[str]) -> Overrides:
    """``--mpc KEY=VALUE`` values, parsed and checked as ``crowdmpc --set mpc.KEY=VALUE`` (the values that
    differ from Table I); a key the rows vary themselves is an error."""
    run = load(None, sets=mpc_sets(texts))
    clash = sorted(ROW_KEYS & {text.partition("=")[0].strip() for text in texts})
    if clash:
        raise ConfigError(f"{', '.join(clash)}: set by --rules and --parallel, not by --mpc")
    return run.mpc_overrides()


class _PhaseClock:
    """Wraps a DMPC's ``_solve_all`` (its local-solve phase): time spent and, when asked, the batches."""

    def __init__(self, solver: DMPC, record: bool = False):
        self.seconds, self.solves = 0.0, 0
        self.batches: list[list[tuple]] = []
        self._solve_all, self._record = solver._solve_all, record
        solver._solve_all = self  # type: ignore[method-assign]

    def __call__(self, jobs):
        if self._record:
            self.batches.append(
                [tuple(np.copy(a) if isinstance(a, np.ndarray) else a for a in j) for j in jobs]
            )
        t0 = time.perf_counter()
        out = self._solve_all(jobs)
        self.seconds += time.perf_counter() - t0
        self.solves += len(jobs)
        return out


def _row(times: list[float], iterations: list[int], outcomes: list[Any], phase: _PhaseClock, j_max: int):
    ms = np.asarray(times) * 1e3
    its = np.asarray(iterations)
    return {
        "median_ms": float(np.median(ms)),
        "p95_ms": float(np.percentile(ms, 95)),
        "p99_ms": float(np.percentile(ms, 99)),
        "steps": int(ms.size),
        "iterations_mean": float(its.mean()),
        "at_j_max": float(np.mean(its >= j_max)),
        "solves_per_step": phase.solves / ms.size,
        "phase_ms_per_step": phase.seconds * 1e3 / ms.size,
        "success": sum(m.success for m in outcomes),
        "collision": sum(m.collision for m in outcomes),
        "timeout": sum(m.timeout for m in outcomes),
        "episodes": len(outcomes),
    }


def closed_loop(
    n_robots: int, n_humans: int, rule: str, modes: list[str], episodes: int, extra: Overrides = ()
) -> dict[str, Any]:
    """Every mode of one (M, rule) on the same seeds, mode after mode within a seed."""
    if rule.startswith("gauss_seidel"):
        modes = ["serial"]  # one solve at a time: nothing to run in parallel
    controllers = {mode: _controller(rule, mode, extra) for mode in modes}
    clocks = {}
    for mode, controller in controllers.items():
        solver = controller.solver(n_robots, n_humans)
        assert isinstance(solver, DMPC)
        # Built now, untimed: a robot's warm IPOPT is otherwise built in the step of its first Fatrop failure,
        # one per robot with threads against one shared in serial (about 1 % of the threads' phase).
        for local_solver in {id(x): x for x in solver.local._solvers}.values():
            local_solver._ipopt(warm=True)
        clocks[mode] = _PhaseClock(solver)
    data: dict[str, dict[str, list]] = {m: {"times": [], "its": [], "outcomes": []} for m in modes}
    same, cut = True, 0
    limit_s = next(iter(controllers.values())).cfg.time_limit_s
    try:
        for seed in episode_bar(episodes, f"M={n_robots} {rule}"):
            results = []
            for mode, controller in controllers.items():
                result = run_episode(
                    controller, seed=seed, scenario="circle", n_humans=n_humans, n_robots=n_robots
                )
                data[mode]["times"].extend(result.solve_times_s)
                data[mode]["its"].extend(result.iterations)
                data[mode]["outcomes"].append(result.metrics)
                results.append(result)
            agree, was_cut = same_before_limit(results, limit_s)
            same, cut = same and agree, cut + was_cut
    finally:
        for controller in controllers.values():
            controller.close()
    j_max = next(iter(controllers.values())).cfg.j_max
    rows = {m: _row(d["times"], d["its"], d["outcomes"], clocks[m], j_max) for m, d in data.items()}
    return cell_report(rows, same, cut)


def same_before_limit(results: Sequence[Any], limit_s: float) -> tuple[bool, bool]:
    """Whether the runs of one seed (``EpisodeResult``s) drove the robots the same way, compared up to the
    first step that took longer than ``limit_s`` in any of them, and whether that cut the comparison short.

    A step past the limit may have stopped its iterations (or failed a solve) by the clock, as a serial step
    at 6 robots on a loaded machine does, and the runs then part for the load's sake; the positions before
    it follow from steps within the limit only, which nothing cut, so they must agree bit for bit."""
    firsts = [np.flatnonzero(np.asarray(r.solve_times_s) > limit_s) for r in results]
    cut = min((int(over[0]) for over in firsts if over.size), default=None)
    end = None if cut is None else cut + 1  # positions 0..cut: the steps before the cut one
    paths = [r.robot_positions[:end] for r in results]
    return all(np.array_equal(paths[0], p) for p in paths[1:]), cut is not None


def cell_report(rows: dict[str, dict[str, Any]], same: bool, cut: int = 0) -> dict[str, Any]:
    """A cell's rows, whether serial and threads drove the same trajectories (``cut``: in how many episodes
    only up to a step past the time limit), and, with both modes, the threads' speed-up (serial / threads)
    of the step median and of the phase: what the table prints, in the JSON too."""
    cell: dict[str, Any] = {"rows": rows, "same": same, "cut": cut}
    if "serial" in rows and "threads" in rows:
        s, t = rows["serial"], rows["threads"]
        cell["speedup"] = {
            "step_median": s["median_ms"] / t["median_ms"],
            "phase": s["phase_ms_per_step"] / t["phase_ms_per_step"],
        }
    return cell


def list_schedule_speedup(durations: np.ndarray, threads: int, longest_first: bool = False) -> float:
    """Serial time over the time ``threads`` threads take when each idle thread takes the next job of a
    batch (no overhead), summed over the batches: ``durations`` (batches, jobs) in seconds. With
    ``longest_first`` the jobs of each batch are taken longest first instead of in order."""
    serial = parallel = 0.0
    for batch in np.asarray(durations, dtype=float):
        order = np.argsort(-batch, kind="stable").tolist() if longest_first else list(range(len(batch)))
        free = [0.0] * threads
        for k in order:
            heapq.heappush(free, heapq.heappop(free) + batch[k])
        serial += float(batch.sum())
        parallel += max(free)
    return serial / parallel


def same_within_limit(first: Sequence[Solution], second: Sequence[Solution]) -> tuple[bool, int]:
    """Whether two paths' solutions of one batch agree bit for bit, leaving out each problem whose solve ran
    past ``time_limit_s`` in either, and how many were so left out: the clock, not the code, ended such a
    solve (IPOPT's max_wall_time, or Fatrop's status set after the fact), as ``same_before_limit`` allows
    for the closed loop."""
    agree, cut = True, 0
    for a, b in zip(first, second, strict=True):
        if a.status in BUDGET_STATUSES or b.status in BUDGET_STATUSES:
            cut += 1
        else:
            agree = agree and np.array_equal(a.accels, b.accels) and a.cost == b.cost
    return agree, cut


def replay(n_robots: int, n_humans: int, rule: str, reps: int, extra: Overrides = ()) -> dict[str, Any]:
    """The local-solve phase alone: one serial episode's batches of M problems, serial vs threads."""
    controller = _controller(rule, "serial", extra)
    solver = controller.solver(n_robots, n_humans)
    assert isinstance(solver, DMPC)
    clock = _PhaseClock(solver, record=True)
    run_episode(controller, seed=0, scenario="circle", n_humans=n_humans, n_robots=n_robots)
    batches = [b for b in clock.batches if len(b) == n_robots]
    threaded = DMPC(solver.cfg.replace(dmpc_parallel="threads"), n_robots, n_humans)
    variants = {"serial": clock._solve_all, "threads": threaded._solve_all}  # DMPC's own two code paths
    for batch in batches:  # untimed: both paths build what they build on first use (IPOPT fallbacks)
        for solve_all in variants.values():
            solve_all(batch)
    seconds = dict.fromkeys(variants, 0.0)
    identical, solves_cut = True, 0
    for r in range(reps):
        for batch in batches:
            outs = {}
            for name in variants if r % 2 == 0 else list(variants)[::-1]:
                t0 = time.perf_counter()
                outs[name] = variants[name](batch)
                seconds[name] += time.perf_counter() - t0
            agree, cut = same_within_limit(outs["serial"], outs["threads"])
            identical, solves_cut = identical and agree, solves_cut + cut
    threaded.close()
    alone = np.full((len(batches), n_robots), np.inf)  # each problem timed on its own, the least of reps
    for _ in range(reps):
        for b, batch in enumerate(batches):
            for k, job in enumerate(batch):
                t0 = time.perf_counter()
                variants["serial"]([job])
                alone[b, k] = min(alone[b, k], time.perf_counter() - t0)
    n = reps * len(batches)
    return {
        "batches": len(batches),
        "reps": reps,
        "serial_ms": seconds["serial"] * 1e3 / n,
        "threads_ms": seconds["threads"] * 1e3 / n,
        "speedup": seconds["serial"] / seconds["threads"],
        "identical": identical,
        "cut": solves_cut,
        "bound_in_order": list_schedule_speedup(alone, threaded._helpers + 1),
        "bound_longest_first": list_schedule_speedup(alone, threaded._helpers + 1, longest_first=True),
    }


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        extra = _checked(parser, args)
        report = _measure(args, extra)
        print_report(report, args, PREDICTOR, extra)
        if args.json:
            write_json(args.json, report)
        return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--robots", type=robot_count, nargs="+", default=[3, 6])
    parser.add_argument("--humans", type=human_count, default=7)
    parser.add_argument(
        "--episodes", type=episode_count, default=3, help="circle episodes per row (seeds 0..)"
    )
    parser.add_argument("--rules", nargs="+", default=list(RULES), help="UPDATE:STOP pairs")
    parser.add_argument("--parallel", nargs="+", choices=PARALLEL_MODES, default=list(PARALLEL_MODES))
    parser.add_argument("--replay", action="store_true", help="also time the local-solve phase alone")
    parser.add_argument("--replay-reps", type=count_in("replay reps", 1), default=3)
    parser.add_argument(
        "--mpc",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an [mpc] value as `crowdmpc --set mpc.KEY=VALUE` takes it, e.g. cost_scale=0.01 (repeatable)",
    )
    parser.add_argument("--json", type=output_file, help="also write the figures to this file")
    return parser


def _checked(parser: argparse.ArgumentParser, args: argparse.Namespace) -> Overrides:
    """The ``--mpc`` overrides, once every number and rule of the command line has been checked (a bad one
    ends the script through ``parser.error`` before any episode)."""
    try:
        extra = mpc_overrides(args.mpc)
    except PipelineError as exc:  # ConfigError and the other errors a value can cause
        parser.error(f"--mpc: {exc}")
    for option in ("robots", "rules", "parallel"):  # the report's cells and rows are keyed by them
        check_distinct(parser, f"--{option}", getattr(args, option))
    for rule in args.rules:
        update, _, stop = rule.partition(":")
        if update not in DMPC_UPDATES or stop not in DMPC_STOPS:
            parser.error(f"rule {rule!r}: UPDATE:STOP with UPDATE in {DMPC_UPDATES}, STOP in {DMPC_STOPS}")
    return extra


def _measure(args: argparse.Namespace, extra: Overrides) -> dict[str, Any]:
    """Every (M, rule) cell, with the load and wall time around them."""
    report: dict[str, Any] = {"load_before": os.getloadavg(), "cpus": os.cpu_count(), "cells": {}}
    report["mpc"] = dict(extra)
    t_start = time.perf_counter()
    for m in args.robots:
        for rule in args.rules:
            key = f"r{m} {rule}"
            cell = closed_loop(m, args.humans, rule, args.parallel, args.episodes, extra)
            if args.replay and len(cell["rows"]) > 1:
                cell["replay"] = replay(m, args.humans, rule, args.replay_reps, extra)
            cell["load"] = os.getloadavg()[0]
            report["cells"][key] = cell
            print(f"done {key} ({time.perf_counter() - t_start:.0f} s, load {cell['load']:.2f})", flush=True)
    report["load_after"] = os.getloadavg()
    report["wall_s"] = time.perf_counter() - t_start
    return report


if __name__ == "__main__":
    raise SystemExit(run_main(main))
