"""Where a Table II episode's time goes: CasADi's C code against the Python around it.

    nice -n 5 .venv/bin/python benchmarks/sweep_floor.py                      # 21 episodes a cell
    nice -n 5 .venv/bin/python benchmarks/sweep_floor.py --episodes-per-cell 41 --json floor.json

Runs a Table II sweep (CMPC and DMPC, 5-9 humans, social_lstm_eth, the paper's method) in this process,
as ``crowdmpc sweep --backend inline`` does (compiled when gcc is found, as sweeps are by default, into a
private compile cache removed at the end: the user's is neither filled nor read), with
every call into CasADi timed: each NLP solve (Fatrop; IPOPT where Fatrop fails or a step starts from
braking), the other buffered functions (the predictor's twin, DMPC's cost maps), the predictor's encoder (a
plain ``casadi.Function`` call, so its DM conversions are in its time) and the solvers' statistics calls. A
cell's first episode builds the cell's NLPs and functions and is left out; it is a circle crossing, so an odd
count per cell times as many circle as perpendicular crossings (Table II's mix).

Prints each part's share of episode time and what the full Table II (10 x 1000 episodes) would take on
``--workers`` cores at this rate, and with no Python at all (the time in CasADi only): the floor that
removing overhead could reach without fewer solves or a cheaper predictor. The timing wrappers add about a
microsecond a call to the Python side. Run it on an idle machine: the figures are per core.
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import json_on_stdout, output_file, private_cache, run_main, write_json  # noqa: E402

TARGET_MIN = 15.0  # issue 16's target for the full table on 2 cores


def table2_episodes() -> int:
    """The full Table II: its cells times the paper's episodes per cell (10 x 1000)."""
    from pipelines.experiments.cells import PAPER_EPISODES_PER_CELL, get_experiment

    return len(get_experiment("table2").cells()) * PAPER_EPISODES_PER_CELL


class CasadiClock:
    """Seconds inside CasADi, by part, for the episode running now; ``close`` undoes the patches."""

    def __init__(self) -> None:
        self.now: collections.defaultdict[str, float] = collections.defaultdict(float)
        self._undo: list[Callable[[], None]] = []

    def add(self, part: str, seconds: float) -> None:
        self.now[part] += seconds

    def timed(self, part: str, call: Callable[..., Any]) -> Callable[..., Any]:
        def run(*args: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return call(*args)
            finally:
                self.add(part, time.perf_counter() - t0)

        return run

    def install(self) -> None:
        from mpc.fastcall import BufferedFunction
        from predictors.learned import LearnedPredictor

        clock = self
        init, stats, encoder = (
            BufferedFunction.__init__,
            BufferedFunction.stats,
            LearnedPredictor.casadi_encoder,
        )

        def buffered_init(self: BufferedFunction, function: Any) -> None:
            init(self, function)
            # Only the evaluation itself: the argument copies and the result copies stay Python's.
            self._trigger = clock.timed(part_of(function), self._trigger)

        def timed_stats(self: BufferedFunction) -> dict:
            t0 = time.perf_counter()
            try:
                return stats(self)
            finally:
                clock.add("solver statistics", time.perf_counter() - t0)

        def timed_encoder(self: LearnedPredictor, n_agents: int, length: int) -> Any:
            return clock.timed("encoder", encoder(self, n_agents, length))

        BufferedFunction.__init__ = buffered_init  # type: ignore[method-assign]
        BufferedFunction.stats = timed_stats  # type: ignore[method-assign]
        LearnedPredictor.casadi_encoder = timed_encoder  # type: ignore[method-assign]
        self._undo.append(lambda: setattr(BufferedFunction, "__init__", init))
        self._undo.append(lambda: setattr(BufferedFunction, "stats", stats))
        self._undo.append(lambda: setattr(LearnedPredictor, "casadi_encoder", encoder))

    def close(self) -> None:
        while self._undo:
            self._undo.pop()()


def part_of(function: Any) -> str:
    """A buffered CasADi function's part: a solver by plugin and NLP, else "twin and cost maps"."""
    kind = function.class_name()
    if kind in ("FatropInterface", "IpoptInterface"):
        nlp = "joint" if function.name().startswith("joint") else "local"
        return f"{kind.removesuffix('Interface').lower()} {nlp}"
    return "twin and cost maps"


@contextmanager
def episodes_timed(clock: CasadiClock, rows: list[dict[str, Any]]) -> Iterator[None]:
    """Every episode the sweep runs, with its wall time and its CasADi time by part, appended to ``rows``."""
    import pipelines.loop.episode as episode

    run_episode = episode.run_episode

    def timed(*args: Any, **kwargs: Any) -> Any:
        clock.now.clear()
        t0 = time.perf_counter()
        result = run_episode(*args, **kwargs)
        rows.append({"cell": kwargs["meta"]["cell"], "wall_s": time.perf_counter() - t0, **clock.now})
        return result

    episode.run_episode = timed  # the sweep's worker imports it from the module at each episode
    try:
        yield
    finally:
        episode.run_episode = run_episode


def measure(episodes_per_cell: int) -> list[dict[str, Any]]:
    """Every episode of a Table II sweep run inline, first episode of each cell left out."""
    from pipelines.experiments.cells import get_experiment
    from pipelines.experiments.sweep import run_sweep
    from pipelines.experiments.sweep_config import SweepConfig
    from pipelines.experiments.worker import jit_available

    clock, rows = CasadiClock(), list[dict[str, Any]]()
    clock.install()
    try:
        with tempfile.TemporaryDirectory(prefix="crowdmpc-floor-") as out, episodes_timed(clock, rows):
            config = SweepConfig(
                get_experiment("table2"),
                Path(out),
                episodes_per_cell,
                backend="inline",
                progress=False,
                jit=jit_available(),
            )
            run_sweep(config)
    finally:
        clock.close()
    seen: set[str] = set()
    steady = []
    for row in rows:
        if row["cell"] in seen:
            steady.append(row)
        seen.add(row["cell"])
    return steady


def summary(rows: list[dict[str, Any]], workers: int) -> dict[str, Any]:
    n = len(rows)
    wall = sum(r["wall_s"] for r in rows) / n
    parts = sorted({k for r in rows for k in r} - {"cell", "wall_s"})
    casadi = {p: sum(r.get(p, 0.0) for r in rows) / n for p in parts}
    in_casadi = sum(casadi.values())
    minutes = table2_episodes() / workers / 60
    target_s = TARGET_MIN / minutes  # seconds an episode may take for the target
    python_s = wall - in_casadi
    if wall <= target_s:  # met at this rate: nothing to cut (the formula below went negative, -672 %)
        cut = 0.0
    elif in_casadi >= target_s or python_s <= 0:  # out of reach even with no Python at all
        cut = 1.0
    else:
        cut = 1 - (target_s - in_casadi) / python_s
    return {
        "episodes": n,
        "workers": workers,
        "episode_ms": wall * 1e3,
        "casadi_ms": {p: s * 1e3 for p, s in casadi.items()},
        "casadi_share": in_casadi / wall,
        "python_ms": (wall - in_casadi) * 1e3,
        "table2_min": wall * minutes,
        "table2_min_without_python": in_casadi * minutes,
        "target_min": TARGET_MIN,
        # the share of the Python time to remove for the target, 0..1 (0: met already; 1: not even then)
        "python_cut_needed_for_target": cut,
    }


def target_verdict(out: dict[str, Any]) -> str:
    """What the target asks of the Python time, in words: met already, a share of it gone, or out of reach."""
    target = f"{out['target_min']:.0f} min"
    if out["table2_min"] <= out["target_min"]:
        return f"{target} is met at this rate on {out['workers']} cores"
    if out["table2_min_without_python"] >= out["target_min"]:
        return f"{target} is out of reach on {out['workers']} cores even with no Python time"
    return f"{target} needs {100 * out['python_cut_needed_for_target']:.0f} % of the Python time gone"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--episodes-per-cell", type=int, default=21, help="one more than is timed (default 21)"
    )
    parser.add_argument("--workers", type=int, default=2, help="cores the projection assumes (default 2)")
    parser.add_argument("--json", type=output_file, help="also write the figures to this file")
    args = parser.parse_args(argv)
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        if args.episodes_per_cell < 2:
            parser.error(f"--episodes-per-cell must be >= 2 (the first of each cell is not timed), got "
                         f"{args.episodes_per_cell}")  # fmt: skip
        if args.workers < 1:
            parser.error(f"--workers must be >= 1, got {args.workers}")
        load = os.getloadavg()[0]
        with private_cache("crowdmpc-floor-cache-"):
            out = summary(measure(args.episodes_per_cell), args.workers)
        out["load"] = [load, os.getloadavg()[0]]
        loads = f"load {load:.2f} -> {out['load'][1]:.2f}"
        print(f"Table II sweep inline: {out['episodes']} timed episodes, {loads}")
        print(f"episode {out['episode_ms']:.1f} ms, of which in CasADi {100 * out['casadi_share']:.1f} %:")
        rows = sorted(out["casadi_ms"].items(), key=lambda kv: -kv[1]) + [
            ("Python and numpy", out["python_ms"])
        ]
        for part, ms in rows:
            print(f"  {part:<22} {ms:7.1f} ms  {100 * ms / out['episode_ms']:5.1f} %")
        print(
            f"full Table II on {args.workers} cores at this rate {out['table2_min']:.1f} min; "
            f"with no Python at all {out['table2_min_without_python']:.1f} min; {target_verdict(out)}"
        )
        if args.json:
            write_json(args.json, out)
        return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
