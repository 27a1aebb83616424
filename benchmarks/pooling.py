"""Social pooling's dense and sparse paths (predictors/nets/pooling.py) side by side, by crowd size.

For each number of agents N (``--agents``), one Social-LSTM training step (default config, ``--pooling``
grid or soft; forward with teacher forcing and backward, as ``crowdmpc train`` runs it) on a batch of
``--batch`` scenes of 21 steps, once with every ``GridPooling`` on the dense path (``sparse = False``: the
``cell_weights`` einsum the export traces) and once on the sparse one. The agents of a scene start around
one point with a Gaussian spread of 0.5 sqrt(N) m, so the density at the crowd's centre (0.64 agents per m²,
some 15 in an agent's 4.8 m grid) is the same whatever N. ``--phase eval`` times a prediction instead
(evaluation: B = 1, no teacher forcing, no gradient).

Each measurement runs in a process of its own, which reports the best step time of ``--repeats``, its peak
resident memory ("peak MB": VmHWM of /proc/self/status; ru_maxrss where there is none) and how far that peak
is above what it held just before the first step ("step MB": what the steps needed). One torch thread unless
``--threads``. The machine is shared: the memory figures do not depend on its load, the times do.

    nice -n 5 .venv/bin/python benchmarks/pooling.py
    nice -n 5 .venv/bin/python benchmarks/pooling.py --agents 20 80 --pooling soft --repeats 3
    nice -n 5 .venv/bin/python benchmarks/pooling.py --phase eval --agents 80 320 640 --json pooling.json
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import check_distinct, count_in, figure, json_on_stdout, output_file, run_main, write_json  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
STEPS = 21  # obs 9 + pred 12, TrajNet++'s window
OBS_LEN = 9
MODES = ("dense", "sparse")


def _memory_kb(key: str) -> int | None:
    """``key`` (VmRSS, VmHWM) of /proc/self/status in KB, or None without /proc."""
    try:
        with open("/proc/self/status", encoding="utf-8") as status:
            return next(int(line.split()[1]) for line in status if line.startswith(f"{key}:"))
    except (OSError, StopIteration):
        return None


def scenes(batch: int, n_agents: int, seed: int = 0):
    """``batch`` scenes of ``n_agents`` walking 0.4 m a step, spread as ``0.5 * sqrt(N)`` m: (B, T, N, 2)."""
    import torch

    generator = torch.Generator().manual_seed(seed)
    start = torch.randn(batch, 1, n_agents, 2, generator=generator) * (0.5 * math.sqrt(n_agents))
    heading = torch.randn(batch, 1, n_agents, 2, generator=generator)
    heading = heading / heading.norm(dim=-1, keepdim=True)
    positions = start + 0.4 * torch.arange(STEPS, dtype=torch.float32)[None, :, None, None] * heading
    return positions, torch.ones(batch, STEPS, n_agents, dtype=torch.bool)


def measure(
    mode: str, n_agents: int, batch: int, pooling: str, phase: str, repeats: int, threads: int
) -> dict[str, Any]:
    """In this process: the best time of ``repeats`` steps, the peak memory (MB) and what the steps added to
    it (NaN without /proc)."""
    import torch

    torch.set_num_threads(threads)

    from predictors.nets.pooling import GridPooling
    from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig

    torch.manual_seed(0)
    net = SocialLSTM(SocialLSTMConfig(pooling=pooling))
    for module in net.modules():
        if isinstance(module, GridPooling):
            module.sparse = mode == "sparse"
    positions, mask = scenes(batch if phase == "train" else 1, n_agents)
    before = _memory_kb("VmRSS")
    times = []
    for _ in range(repeats):
        net.zero_grad()
        t0 = time.perf_counter()
        if phase == "train":
            out, _ = net.train()(positions, mask, OBS_LEN, STEPS - OBS_LEN, teacher_forcing=True)
            out[..., :2].square().mean().backward()
        else:
            with torch.no_grad():
                net.eval()(positions, mask, OBS_LEN, STEPS - OBS_LEN, teacher_forcing=False)
        times.append(time.perf_counter() - t0)
    peak = _memory_kb("VmHWM")
    if peak is None:  # no /proc: ru_maxrss (KB on Linux, bytes on macOS), and no base to subtract
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // (1024 if sys.platform == "darwin" else 1)
    step = float("nan") if before is None else (peak - before) / 1024
    return {"seconds": min(times), "peak_mb": peak / 1024, "step_mb": step}


def measure_apart(mode: str, n_agents: int, args: argparse.Namespace) -> dict[str, Any]:
    """``measure`` in a fresh interpreter, so that each peak is its own (a process's peak never falls)."""
    code = (
        "import json, sys\n"
        f"sys.path.insert(0, {str(Path(__file__).resolve().parent)!r})\n"
        "import pooling\n"
        f"print(json.dumps(pooling.measure({mode!r}, {n_agents}, {args.batch}, {args.pooling!r}, "
        f"{args.phase!r}, {args.repeats}, {args.threads})))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
        env=os.environ | {"PYTHONPATH": str(ROOT)},
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--agents", type=count_in("agents", 1), nargs="+", default=[20, 80, 320])
    parser.add_argument("--batch", type=count_in("batch", 1), default=8, help="scenes a training batch")
    parser.add_argument("--pooling", choices=("grid", "soft"), default="grid")
    parser.add_argument("--phase", choices=("train", "eval"), default="train")
    parser.add_argument("--repeats", type=count_in("repeats", 1), default=3)
    parser.add_argument("--threads", type=count_in("threads", 1), default=1)
    parser.add_argument("--json", type=output_file, help="also write the rows to this file")
    args = parser.parse_args(argv)
    check_distinct(parser, "--agents", args.agents)
    with json_on_stdout(args.json):
        batch = args.batch if args.phase == "train" else 1
        print(
            f"Social-LSTM {args.pooling} pooling, {args.phase} step, B = {batch}, {STEPS} steps, "
            f"{args.threads} thread(s); best of {args.repeats}; memory: each process's own peak"
        )
        print(
            f"{'N':>5} | {'dense s':>8} {'peak MB':>8} {'step MB':>8} | "
            f"{'sparse s':>8} {'peak MB':>8} {'step MB':>8} | {'speed-up':>8}"
        )
        rows = []
        for n_agents in args.agents:
            row: dict[str, Any] = {"agents": n_agents}
            for mode in MODES:
                row[mode] = measure_apart(mode, n_agents, args)
            dense, sparse = row["dense"], row["sparse"]
            print(
                f"{n_agents:>5} | {dense['seconds']:>8.3f} {dense['peak_mb']:>8.0f} "
                f"{figure(dense['step_mb'], '>8.0f')} | {sparse['seconds']:>8.3f} {sparse['peak_mb']:>8.0f} "
                f"{figure(sparse['step_mb'], '>8.0f')} | {dense['seconds'] / sparse['seconds']:>7.1f}x",
                flush=True,
            )
            rows.append(row)
        if args.json is not None:
            write_json(args.json, {"args": vars(args), "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
