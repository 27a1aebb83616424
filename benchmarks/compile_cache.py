"""The compile cache on the predictor ablation: wall time with a cold cache, a warm cache and ``--jit off``.

    nice -n 5 .venv/bin/python benchmarks/compile_cache.py                       # 7 predictors x 2 episodes
    nice -n 5 .venv/bin/python benchmarks/compile_cache.py --episodes-per-cell 4 --json cache.json

Runs ``crowdmpc sweep --experiment predictors --predictors <the original seven> --episodes-per-cell 2`` three
times, as a user would (a subprocess each, default workers and backend), each into a fresh output directory,
all with one private, initially empty ``$CROWDMPC_CACHE`` (the user's cache is not touched):

1. ``--jit on``, cold: every NLP is compiled (once per machine: the workers share the entries);
2. ``--jit on``, warm: the entries of run 1 are loaded;
3. ``--jit off``: nothing compiled, CasADi's interpreted functions.

Prints each run's wall time with the load average before and after it (the machine is shared: compare runs
of similar load), the CPU the episodes themselves used, the cache's entries, and whether the three runs'
episode metrics agree.

Then, in this process, the numbers behind ``--jit auto`` (mpc.compile_cache.COMPILE_S and
SAVING_PER_EPISODE_S): for CMPC's joint NLP and DMPC's local one (3 robots, 7 humans), the wall time and CPU
(gcc included) of a cold compile, the wall time of a warm load, and the CPU per closed-loop episode with and
without jit (``--payback-episodes`` episodes each, constant-velocity predictions, after one warm-up
episode); the compile's CPU over the saving per episode is the number of episodes that repays it.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import count_in, json_on_stdout, output_file, predictor_name, run_main, write_json  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
# The predictor ablation as first measured (283 s with jit, 19 s without): its default list then.
ORIGINAL_SEVEN = (
    "constant_velocity,vanilla_lstm_eth,social_lstm_eth,social_lstm_soft_eth,social_gan_eth,"
    "social_lstm_synth,orca_oracle"
)


def predictor_names(text: str) -> str:
    """An argparse ``type``: ``--predictors`` as ``crowdmpc sweep`` takes it (its ``predictor_list``: 1 to
    the most names a swap table takes, each well-formed), each registered or in a zoo (``predictor_name``),
    none twice; refused now with the parser's one line, not by the first sweep's exit status."""
    from pipelines.commands import first_repeat
    from pipelines.commands.sweep_options import predictor_list

    names = predictor_list(text)
    for name in names:
        predictor_name(name)
    repeated = first_repeat(names)
    if repeated is not None:
        raise argparse.ArgumentTypeError(f"{repeated!r} is named more than once")
    return ",".join(names)


def run_sweep(out: Path, jit: str, episodes: int, predictors: str, env: dict[str, str]) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "pipelines.cli", "sweep", "--experiment", "predictors",
           "--predictors", predictors, "--episodes-per-cell", str(episodes), "--jit", jit,
           "--no-progress", "--out", str(out)]  # fmt: skip
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"sweep failed ({done.returncode}): {' '.join(cmd)}\n{done.stderr[-3000:]}")
    records = [
        json.loads(line)
        for line in (out / "episodes.jsonl").read_text(encoding="utf-8").splitlines()
        if line.strip()
    ]
    return {
        "jit": jit,
        "wall_s": wall,
        "load_before": load_before,
        "load_after": os.getloadavg(),
        "episodes": len(records),
        "episode_cpu_s": sum(r["cpu_s"] for r in records),
        "metrics": {r["key"]: r["metrics"] for r in records},
    }


def cpu_with_children() -> float:
    """CPU seconds of this process and of its finished children (gcc, which CasADi runs through system())."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def payback(episodes: int, cache_root: Path) -> None:
    """Compile time, warm load time and CPU per episode with and without jit, per NLP kind."""
    from mpc import compile_cache
    from mpc.config import MPCConfig
    from mpc.nlp import JointNLP, LocalNLP
    from pipelines.loop.controllers import ControllerSpec, make_controller
    from pipelines.loop.episode import run_episode
    from predictors.text_table import counted

    os.environ[compile_cache.CACHE_ENV] = str(cache_root)  # empty: the first build compiles
    for controller, nlp in (("cmpc", JointNLP), ("dmpc", LocalNLP)):
        builds, build_cpu = [], []
        for _ in range(2):  # cold, then warm
            t0, c0 = time.perf_counter(), cpu_with_children()
            nlp(MPCConfig(jit=True), 3, 7)
            builds.append(time.perf_counter() - t0)
            build_cpu.append(cpu_with_children() - c0)
        cpu = {}
        for jit in (False, True):
            c = make_controller(ControllerSpec(controller, "constant_velocity"), jit=jit)
            run_episode(c, seed=0, scenario="circle", n_humans=7)  # builds (compiles, the first time)
            t0 = time.process_time()
            for k in range(episodes):
                run_episode(c, seed=k // 2, scenario=("circle", "perpendicular")[k % 2], n_humans=7)
            cpu[jit] = (time.process_time() - t0) / episodes
        saving = cpu[False] - cpu[True]
        kind = "joint" if controller == "cmpc" else "local"
        # whole episodes: 2.87 s of compile at 0.255 s saved an episode is repaid by the twelfth, not the 11th
        if saving > 0:
            repaid = f"a compile repaid after {counted(math.ceil(build_cpu[0] / saving), 'episode')}"
        else:
            repaid = "a compile never repaid"
        print(
            f"{controller} ({kind} NLP, 7 humans): compile {builds[0]:.2f} s wall, {build_cpu[0]:.2f} s CPU "
            f"(gcc included), warm load "
            f"{builds[1] * 1e3:.0f} ms; CPU per episode {cpu[False]:.3f} s without jit, {cpu[True]:.3f} s "
            f"with: saves {saving:.3f} s, {repaid} "
            f"(auto assumes {compile_cache.COMPILE_S[kind]} s and {compile_cache.SAVING_PER_EPISODE_S[kind]} "
            f"s); load {os.getloadavg()[0]:.2f}",
            flush=True,
        )


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes-per-cell", type=count_in("episodes per cell", 1), default=2)
    parser.add_argument(
        "--predictors",
        type=predictor_names,
        default=ORIGINAL_SEVEN,
        help="comma-separated, registered or in a zoo (default: the seven)",
    )
    parser.add_argument(
        "--payback-episodes",
        type=count_in("payback episodes", 0),
        default=8,
        help="per variant (0: skip that part)",
    )
    parser.add_argument("--json", type=output_file, help="also write the sweeps' numbers here")
    args = parser.parse_args()
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        sys.path.insert(0, str(ROOT))
        from mpc import cache_admin, compile_cache
        from predictors.text_table import counted

        with tempfile.TemporaryDirectory(prefix="compile-cache-bench-") as tmp:
            env = os.environ | {compile_cache.CACHE_ENV: str(Path(tmp) / "cache")}
            runs = {}
            for label, jit in (("cold", "on"), ("warm", "on"), ("off", "off")):
                runs[label] = run_sweep(Path(tmp) / label, jit, args.episodes_per_cell, args.predictors, env)
                r = runs[label]
                print(
                    f"{label:>4} (--jit {jit:>3}): {r['wall_s']:6.1f} s wall, "
                    f"{counted(r['episodes'], 'episode')} using "
                    f"{r['episode_cpu_s']:5.1f} s CPU; load {r['load_before'][0]:.2f} before, "
                    f"{r['load_after'][0]:.2f} after",
                    flush=True,
                )
            stats = cache_admin.info(Path(tmp) / "cache" / compile_cache.SUBDIR)
            entries = f"{stats.entries} {'entry' if stats.entries == 1 else 'entries'}"
            print(f"cache: {entries}, {stats.size_bytes / 1024:.0f} KiB; {stats.compiler}")
            base = runs["off"]["metrics"]
            for label in ("cold", "warm"):
                same = sum(runs[label]["metrics"].get(k) == m for k, m in base.items())
                print(f"metrics {label} vs off: {same}/{len(base)} episodes identical")
            compile_s = runs["cold"]["wall_s"] - runs["warm"]["wall_s"]
            saving = (runs["off"]["wall_s"] - runs["warm"]["wall_s"]) / runs["off"]["episodes"]
            print(
                f"this sweep: cold - warm {compile_s:.1f} s wall; off - warm {saving:.2f} s wall per episode"
            )
            from pipelines.commands.sweep_jit import jit_pays
            from pipelines.experiments.cells import EXPERIMENTS

            swap = EXPERIMENTS["predictors"].with_predictors(args.predictors.split(","))
            print(f"--jit auto would compile: {jit_pays(swap.cells(), args.episodes_per_cell)}")
            if args.payback_episodes > 0:
                payback(args.payback_episodes, Path(tmp) / "payback-cache")
        if args.json:
            summary = {k: {f: v for f, v in r.items() if f != "metrics"} for k, r in runs.items()}
            write_json(args.json, summary)
        return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
