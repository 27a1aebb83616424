"""Kill a sweep again and again, then let it finish: is every planned episode recorded exactly once, and is no
worker scratch left behind?

    .venv/bin/python benchmarks/sweep_kills.py        # 10 kills, seed 0, Table II, constant velocity
    .venv/bin/python benchmarks/sweep_kills.py --kills 20 --seed 3 --episodes-per-cell 20

Each round starts ``crowdmpc sweep`` (process pool, 2 workers) on the same directory and sends SIGKILL to the
driver's whole process group at a random moment (seeded) between 0.5 s and 4 s after the start; a last run
finishes the sweep. Prints per round how many records there were, then planned vs recorded, duplicate keys,
torn lines, and the crowdmpc scratch folders left in the temp directory. The sweeps get a temp directory of
their own (``TMPDIR``), so that another crowdmpc run on a shared machine, whose scratch comes and goes in
the system's, is not counted as theirs.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pipelines.errors import PipelineError
from pipelines.experiments.cells import EXPERIMENTS
from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import count_in, predictor_name, run_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def records(out: Path) -> list[str]:
    path = out / "episodes.jsonl"
    if not path.exists():
        return []
    return [line for line in path.read_text(encoding="utf-8").split("\n") if line.strip()]


def scratch(tmp: Path) -> set[str]:
    return {p.name for p in tmp.glob("crowdmpc-*") if p.is_dir()}


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--kills", type=count_in("kills", 0), default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--experiment", choices=sorted(EXPERIMENTS), default="table2")
    parser.add_argument(
        "--predictor",
        type=predictor_name,
        help="every method's predictor (default constant_velocity where the experiment can swap it)",
    )
    parser.add_argument("--episodes-per-cell", type=count_in("episodes per cell", 1), default=12)
    args = parser.parse_args()
    if not EXPERIMENTS[args.experiment].predictor_swappable:
        if args.predictor is not None:  # the sweep refuses it in every round
            parser.error(f"--predictor: experiment {args.experiment!r} has no predictor to replace")
    elif args.predictor is None:
        args.predictor = "constant_velocity"
    rng = random.Random(args.seed)
    with tempfile.TemporaryDirectory(prefix="sweep-kills-") as tmp:
        out = Path(tmp) / "sweep"
        # The sweeps' own temp directory: in the system's, any other crowdmpc sweep running meanwhile (a
        # test suite beside this) made scratch folders that were counted as left behind, and exit 1.
        temp = Path(tmp) / "temp"
        temp.mkdir()
        env = {**os.environ, "TMPDIR": str(temp)}
        cmd = [sys.executable, "-m", "pipelines.cli", "sweep", "--experiment", args.experiment,
               "--episodes-per-cell", str(args.episodes_per_cell), "--workers", "2", "--backend", "process",
               "--jit", "off", "--no-progress", "--out", str(out)]  # fmt: skip
        if args.predictor:
            cmd += ["--predictor", args.predictor]
        for k in range(args.kills):
            proc = subprocess.Popen(cmd, cwd=ROOT, env=env, start_new_session=True, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.DEVNULL)  # fmt: skip
            delay = rng.uniform(0.5, 4.0)
            time.sleep(delay)
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            print(f"kill {k + 1:2d} after {delay:.2f} s: {counted(len(records(out)), 'record')}")
        done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
        if done.returncode != 0:  # the sweep's own words: what a "no sweep.json" below would have hidden
            said = "\n".join(done.stderr.strip().splitlines()[-20:])
            print(f"the final sweep exited {done.returncode}:\n{said}", file=sys.stderr)
            if not (out / "sweep.json").is_file():
                raise PipelineError(f"the sweep failed (exit {done.returncode}) before it planned a run")
        lines = records(out)
        keys, torn = [], 0
        for line in lines:  # the last run repairs a line a kill cut; one left here is a failure
            try:
                keys.append(json.loads(line)["key"])
            except (ValueError, KeyError, TypeError):
                torn += 1
        sweep = json.loads((out / "sweep.json").read_text(encoding="utf-8"))
        planned = sweep["runs"][-1]["planned"]
        print(
            f"final run exit {done.returncode}; planned {planned}, recorded {len(lines)}, distinct "
            f"{len(set(keys))}, duplicates {len(keys) - len(set(keys))}, torn lines {torn}"
        )
        left = scratch(temp)
        print(f"crowdmpc scratch folders left in the sweeps' temp directory: {len(left)} {sorted(left)[:5]}")
    return 0 if planned == len(lines) == len(set(keys)) and not torn and not left else 1


if __name__ == "__main__":
    raise SystemExit(run_main(main))
