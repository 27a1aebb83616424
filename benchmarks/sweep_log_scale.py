r"""Time and peak memory of reading a sweep's episode log at 10 to 1000 times the paper's Table II.

Runs a small real sweep (``--experiment``, default table2, at ``--humans``, default 5; 2 episodes a cell,
inline) in a temporary folder. Then, for each of ``--episodes`` (the whole log, split evenly over the cells,
at most 100,000 a cell as a sweep takes: a million table2 records need its 10 cells, --humans 5 6 7 8 9),
writes a sweep directory holding that many records, each a copy of a real one under the plan's next key
(cell, scenario, seed as the schedule gives them), so that every line passes the log's checks, and sweep.json
with the plan's episodes per cell. In that directory, each in a fresh process: (a) ``crowdmpc sweep
--report-only`` (pipelines/experiments/log.py, summary, report, tables, the plots: the tables and plots of
every cell), (b) a resume of the whole plan (``run_sweep``: loads the log, checks the finished episodes'
predictors and margins, finds nothing to run) and (c) ``crowdmpc compare a=DIR b=DIR`` (both runs held at
once, every episode paired). Prints each one's wall time and peak resident memory (the
child's own, as benchmarks/review_memory.py reads it) and the log's size. The machine is shared: the memory
figures do not depend on its load, the times do. A million records take ~2.6 GB of disk for table2. A child
that fails prints its own error.

    nice -n 10 .venv/bin/python benchmarks/sweep_log_scale.py
    nice -n 10 .venv/bin/python benchmarks/sweep_log_scale.py --episodes 10000 100000 1000000 \
        --humans 5 6 7 8 9
    nice -n 10 .venv/bin/python benchmarks/sweep_log_scale.py --experiment baselines --episodes 1000 \
        --json scale.json
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import count_in, human_count, json_on_stdout, output_file, run_main, write_json  # noqa: E402
from review_memory import PEAK_SOURCES, peak  # noqa: E402

from pipelines.experiments.cells import EXPERIMENTS  # noqa: E402
from pipelines.experiments.log import EPISODES_FILE, SWEEP_FILE  # noqa: E402
from pipelines.experiments.sweep_config import MAX_EPISODES_PER_CELL  # noqa: E402
from pipelines.experiments.tasks import scenario_schedule  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEED_EPISODES = 2  # a cell's real episodes: a circle and a perpendicular crossing
# (b) the resume of a sweep whose every planned episode is recorded, as `crowdmpc sweep` runs it
RESUME = (
    "import sys\n"
    "from pathlib import Path\n"
    "from pipelines.experiments.cells import get_experiment\n"
    "from pipelines.experiments.sweep import run_sweep\n"
    "from pipelines.experiments.sweep_config import SweepConfig\n"
    "name, out, per_cell = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3])\n"
    "humans = tuple(int(h) for h in sys.argv[4].split(','))\n"
    "config = SweepConfig(get_experiment(name), out, per_cell, humans=humans, backend='inline', "
    "progress=False, jit=False)\n"
    "outcome = run_sweep(config)\n"
    "assert outcome.ran == 0 and outcome.already_done == outcome.planned, outcome\n"
)


def seed_sweep(out: Path, experiment: str, humans: str) -> None:
    """The real records to copy: ``SEED_EPISODES`` episodes a cell, run as a user runs them."""
    command = [sys.executable, "-m", "pipelines.cli", "sweep", "--experiment", experiment, "--humans"]
    command += [humans, "--episodes-per-cell", str(SEED_EPISODES), "--backend", "inline"]
    command += ["--no-progress", "--jit", "off", "--out", str(out)]
    env = os.environ | {"PYTHONPATH": str(ROOT)}
    subprocess.run(
        command, cwd=ROOT, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env
    )


def multiply(seed: Path, out: Path, per_cell: int) -> int:
    """``out`` as a sweep directory of ``per_cell`` episodes in each of ``seed``'s cells, every record a copy
    of one of ``seed``'s under the key the plan gives episode i; returns the log's size in bytes."""
    out.mkdir(parents=True, exist_ok=True)
    meta = json.loads((seed / SWEEP_FILE).read_text(encoding="utf-8"))
    run = meta["runs"][-1]
    run["episodes_per_cell"] = per_cell
    run["planned"] = per_cell * len(run["cells"])
    if isinstance(run.get("config"), dict):  # run_sweep's own line without one: the CLI records it
        # --report-only plans from the run's recorded config, not the line's count: left at the seed's 2,
        # the report tabulated 2 episodes a cell of the whole log
        run["config"]["sweep"]["episodes_per_cell"] = per_cell
    (out / SWEEP_FILE).write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")
    templates: dict[str, list[dict[str, Any]]] = {}
    with open(seed / EPISODES_FILE, encoding="utf-8") as f:
        for line in f:
            record = json.loads(line)
            templates.setdefault(record["cell"], []).append(record)
    for records in templates.values():
        records.sort(key=lambda r: r["index"])
    schedule = scenario_schedule(per_cell, run["seed"])
    with open(out / EPISODES_FILE, "w", encoding="utf-8") as f:
        for i, (scenario, seed_number) in enumerate(schedule):
            for cell, records in templates.items():
                record = records[i % len(records)]  # the same scenario: index i % 2 is its own
                copy = record | {"index": i, "seed": seed_number, "scenario": scenario}
                copy["key"] = f"{cell}/{scenario}/{seed_number}"
                f.write(json.dumps(copy, separators=(",", ":")) + "\n")
    return (out / EPISODES_FILE).stat().st_size


def report_code(experiment: str) -> str:
    """(a): ``crowdmpc sweep --report-only`` of the folder given as the first argument."""
    return (
        "import contextlib, io, sys\n"
        "from pipelines.cli import main\n"
        f"argv = ['sweep', '--experiment', {experiment!r}, '--out', sys.argv[1], '--report-only']\n"
        "with contextlib.redirect_stdout(io.StringIO()):  # the table; its errors go to stderr\n"
        "    status = main(argv)\n"
        "if status:\n"
        "    sys.exit(status)\n"
    )


# (c) compare of the folder with itself: two runs of every record held at once, as compare holds them
COMPARE = (
    "import contextlib, io, sys\n"
    "from pipelines.cli import main\n"
    "argv = ['compare', 'a=' + sys.argv[1], 'b=' + sys.argv[1], '--no-progress']\n"
    "with contextlib.redirect_stdout(io.StringIO()):\n"
    "    status = main(argv)\n"
    "if status:\n"
    "    sys.exit(status)\n"
)


def measured(code: str, *args: str) -> tuple[float, float, str]:
    """review_memory's ``peak``; a child that fails shows its own error, not only its exit status."""
    try:
        return peak(code, *args)
    except subprocess.CalledProcessError as exc:
        raise RuntimeError(f"the measured process failed: {exc.stderr.strip()[-2000:]}") from None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--episodes",
        type=count_in("episodes", 1),
        nargs="+",
        default=[10_000, 100_000],
        help="records in the log, all cells together (default: 10000 100000)",
    )
    parser.add_argument("--experiment", choices=sorted(EXPERIMENTS), default="table2")
    parser.add_argument("--humans", type=human_count, nargs="+", default=[5], help="crowd sizes (default 5)")
    parser.add_argument("--json", type=output_file, help="also write the rows to this file")
    args = parser.parse_args(argv)
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        cells = len(EXPERIMENTS[args.experiment].cells(args.humans))
        if max(args.episodes) // cells > MAX_EPISODES_PER_CELL:  # sweep.json's plan would be refused
            parser.error(
                f"--episodes {max(args.episodes)}: {max(args.episodes) // cells} a cell over {cells} cells, "
                f"beyond the {MAX_EPISODES_PER_CELL} a sweep takes; give more --humans"
            )
        humans = ",".join(map(str, sorted(set(args.humans))))
        rows = []
        with tempfile.TemporaryDirectory(prefix="sweep-log-scale-") as tmp:
            seed = Path(tmp) / "seed"
            seed_sweep(seed, args.experiment, humans)
            print(f"{args.experiment}, {cells} cells at {humans} humans; records copied from a real sweep")
            head = ("episodes", "log MB", "report s", "report MB", "resume s", "resume MB", "compare s")
            head += ("compare MB",)
            widths = (9, 8, 9, 10, 9, 10, 10, 11)
            print(" ".join(f"{h:>{w}}" for h, w in zip(head, widths, strict=True)))
            read_from = ""
            for episodes in sorted(set(args.episodes)):
                per_cell = max(1, episodes // cells)
                folder = Path(tmp) / f"log{episodes}"
                size = multiply(seed, folder, per_cell)
                report_mb, report_s, read_from = measured(report_code(args.experiment), str(folder))
                resume_mb, resume_s, _ = measured(RESUME, args.experiment, str(folder), str(per_cell), humans)
                compare_mb, compare_s, _ = measured(COMPARE, str(folder))
                row = {
                    "episodes": per_cell * cells,
                    "log_mb": size / 1e6,
                    "report_s": report_s,
                    "report_peak_mb": report_mb,
                    "resume_s": resume_s,
                    "resume_peak_mb": resume_mb,
                    "compare_s": compare_s,
                    "compare_peak_mb": compare_mb,
                }
                rows.append(row)
                print(
                    f"{row['episodes']:9d} {row['log_mb']:8.1f} {report_s:9.1f} {report_mb:10.0f} "
                    f"{resume_s:9.1f} {resume_mb:10.0f} {compare_s:10.1f} {compare_mb:11.0f}"
                )
                shutil.rmtree(folder)  # the next, larger log is not written beside this one
            print(f"peak memory: {PEAK_SOURCES[read_from]}")
        if args.json:
            write_json(args.json, {"experiment": args.experiment, "humans": humans, "rows": rows})
        return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
