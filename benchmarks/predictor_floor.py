"""Is the predictor's CasADi evaluation at its floor? The exported encoder and twin against their expansion to
scalar operations (SX), evaluated by CasADi and, with ``--compile``, compiled with gcc.

The IBR loop evaluates a learned predictor twice over: the encoder of the observed past once a control step,
the twin (the decoder rolled over the horizon against the robots' plan) at every IBR iteration. Both are
exported as MX graphs of dense matrix operations (predictors/export). If that evaluation were interpretive
overhead, expanding it to scalar operations and compiling them would remove it; if it is arithmetic, the
scalar count says how much there is and compiled code is no faster. For each function this prints the MX
instructions, the scalar operations of its SX expansion, the time a call as the loop makes it (MX, through
mpc/fastcall.py's buffers) and as SX, the nanoseconds per scalar operation, and the largest difference of
the SX results from the MX ones (rounding: at most a few ulps); ``--compile`` adds the generated C's size,
gcc's time and the compiled call.
gcc on the encoder's expansion takes minutes (about 12 at -O1 for social_lstm_eth, 10 agents), hence opt-in.

    nice -n 5 .venv/bin/python benchmarks/predictor_floor.py
    nice -n 5 .venv/bin/python benchmarks/predictor_floor.py --compile twin --opt=-O1
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mpc.compile_cache import compiler  # noqa: E402
from mpc.fastcall import BufferedFunction  # noqa: E402
from pipelines.errors import PipelineError  # noqa: E402
from predictors.export.parity import crossing_scene  # noqa: E402
from predictors.learned import LearnedPredictor  # noqa: E402
from predictors.registry import load_predictor  # noqa: E402
from predictors.text_table import counted  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import count_in, figure, predicted_humans, robot_count, run_main  # noqa: E402


def per_call_us(function, args: list[np.ndarray], calls: int) -> tuple[float, list[np.ndarray]]:
    """Median microseconds a call, and the outputs as flat arrays."""
    out = function(*args)
    times = []
    for _ in range(calls):
        start = time.perf_counter()
        function(*args)
        times.append(time.perf_counter() - start)
    flat = [np.asarray(o, dtype=float).ravel() for o in (out if isinstance(out, (list, tuple)) else [out])]
    return float(np.median(times) * 1e6), flat


def largest_difference(a: list[np.ndarray], b: list[np.ndarray]) -> float:
    return max(float(np.max(np.abs(x - y), initial=0.0)) for x, y in zip(a, b, strict=True))


def compiled(function: ca.Function, opt: str, folder: Path) -> tuple[ca.Function, float, float]:
    """``function`` generated as C and compiled with gcc ``opt``: (loaded function, MB of C, gcc seconds)."""
    cc = compiler()
    if cc is None:
        raise SystemExit("--compile needs gcc on the PATH")
    name = f"floor_{function.name()}"
    generator = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    generator.add(function)
    generator.generate(str(folder) + os.sep)
    source, library = folder / f"{name}.c", folder / f"{name}.so"
    start = time.perf_counter()
    command = [cc.path, opt, "-fPIC", "-shared", str(source), "-o", str(library)]
    done = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, check=False)
    if done.returncode != 0:  # a flag gcc refuses (--opt=-Qbogus), a full disk: its words, not a traceback
        said = [line for line in done.stdout.splitlines() if line.strip()]
        why = next((line for line in said if "error" in line), said[-1] if said else "no message")
        raise PipelineError(f"gcc {opt} failed on {function.name()}'s C (exit {done.returncode}): {why}")
    seconds = time.perf_counter() - start
    return ca.external(function.name(), str(library)), source.stat().st_size / 1e6, seconds


def functions(predictor: LearnedPredictor, n_humans: int, n_robots: int, horizon: int):
    """The loop's two evaluations with inputs from a crossing scene: ``{name: (function, args)}``."""
    history, mask, humans, plan = crossing_scene(n_humans, n_robots, horizon, predictor.obs_len)
    pos, seen, _ = predictor._prepare(history, mask, humans)
    encoder = predictor.casadi_encoder(pos.shape[1], pos.shape[0])
    twin = predictor.to_casadi(n_humans, n_robots, horizon)
    context = predictor.encode(history, mask, humans)
    return {
        "encoder": (encoder, [pos.ravel(), seen.ravel().astype(float)]),
        "twin": (twin, [context, plan.ravel()]),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--model", default="social_lstm_eth")
    parser.add_argument(
        "--humans", type=predicted_humans, default=7, help="at least 1: the twin predicts the humans"
    )
    parser.add_argument("--robots", type=robot_count, default=3)
    parser.add_argument("--horizon", type=count_in("horizon", 1), default=4)
    parser.add_argument("--calls", type=count_in("calls", 1), default=300)
    parser.add_argument("--compile", choices=("none", "twin", "encoder", "both"), default="none")
    parser.add_argument(
        "--opt",
        default="-O1",
        help="gcc's optimisation flag for --compile, given as --opt=-O2 (a bare -O2 reads as an option)",
    )
    args = parser.parse_args(argv)
    predictor = load_predictor(args.model)
    if not isinstance(predictor, LearnedPredictor):  # a user error: one line and exit 2, as crowdmpc's
        parser.error(f"--model {args.model} is not a learned predictor: it has no CasADi encoder or twin")
    print(
        f"{args.model}, {counted(args.humans, 'human')} + {counted(args.robots, 'robot')}, "
        f"H = {args.horizon}, "
        f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"
    )
    to_compile = {"none": (), "twin": ("twin",), "encoder": ("encoder",), "both": ("encoder", "twin")}
    for name, (function, inputs) in functions(predictor, args.humans, args.robots, args.horizon).items():
        mx_us, mx_out = per_call_us(BufferedFunction(function), inputs, args.calls)
        expanded = function.expand()
        scalars = expanded.n_instructions()
        sx_us, sx_out = per_call_us(BufferedFunction(expanded), inputs, max(10, args.calls // 10))
        per_scalar = figure(1e3 * mx_us / scalars if scalars else math.nan, ".2f")  # none: no arithmetic
        print(
            f"{name:8} MX {function.n_instructions():5d} instructions {mx_us:8.1f} us a call "
            f"({per_scalar} ns a scalar operation) | SX {scalars:8d} operations "
            f"{sx_us:8.1f} us, differs by {largest_difference(mx_out, sx_out):.1e}"
        )
        if name in to_compile[args.compile]:
            with tempfile.TemporaryDirectory(prefix="crowdmpc_floor_") as folder:
                library, megabytes, gcc_s = compiled(expanded, args.opt, Path(folder))
                c_us, c_out = per_call_us(BufferedFunction(library), inputs, args.calls)
            print(
                f"{'':8} compiled SX (gcc {args.opt}): {megabytes:.1f} MB of C, {gcc_s:.0f} s to compile, "
                f"{c_us:.1f} us a call ({mx_us / c_us:.2f}x the MX speed), differs by "
                f"{largest_difference(mx_out, c_out):.1e}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
