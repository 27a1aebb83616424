r"""Peak memory of `crowdmpc review DIR` against the number of recordings, beside reading them all at once.

Records ``--episodes`` episodes (``--controller``, default CMPC, with ``--predictor``, default constant
velocity, and ``--humans``, default 7; circle and perpendicular in turn, seeds 0..) into a temporary folder
and copies them until it holds ``--files`` recordings; then, each in a fresh process, (a) ``crowdmpc review
DIR --json`` (pipelines/logs/digest.py: one recording in memory at a time) and (b) every recording read into
one list, as a folder's review held them before. Prints each one's peak resident memory (the child's own,
``VmHWM`` of /proc/self/status; else ``ru_maxrss``, which a child inherits from this script, and the header
says so) and wall time, and (b)'s memory per recording above the interpreter's: what a review that held them
would need for a sweep's thousands. The machine is shared: the memory figures do not depend on its load, the
times do.

    nice -n 10 .venv/bin/python benchmarks/review_memory.py
    nice -n 10 .venv/bin/python benchmarks/review_memory.py --files 50 200 1000 --episodes 4
    nice -n 10 .venv/bin/python benchmarks/review_memory.py --controller dmpc --predictor social_lstm_eth \
        --humans 9
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pipelines.logs.recording import McapEpisodeRecorder
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    check_distinct,
    count_in,
    episode_count,
    human_count,
    json_on_stdout,
    output_file,
    predictor_name,
    run_main,
    write_json,
)

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ("circle", "perpendicular")
# Each measurement in a process of its own, which prints its own peak resident memory last, on stderr: where
# it was read from, and KB. Linux's VmHWM (/proc/self/status) is the peak of the process's own memory, which
# exec starts afresh; ru_maxrss is not: a child keeps the peak of the process it was forked from, so every
# figure read from it was floored at this script's own peak (all 110 MB; 347 MB after recording DMPC with an
# LSTM, where a fresh interpreter peaks at 88 MB). Without /proc (macOS) ru_maxrss it is, which says so (in
# bytes there, KB on Linux).
PEAK = (
    "import resource, sys\n"
    "try:\n"
    "    with open('/proc/self/status') as status:\n"
    "        kb = next(int(line.split()[1]) for line in status if line.startswith('VmHWM:'))\n"
    "    read_from = 'VmHWM'\n"
    "except (OSError, StopIteration):\n"
    "    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
    "    kb //= 1024 if sys.platform == 'darwin' else 1\n"
    "    read_from = 'ru_maxrss'\n"
    "print(read_from, kb, file=sys.stderr)\n"
)
# What each source measures, for the printed header.
PEAK_SOURCES = {
    "VmHWM": "each process's own peak (VmHWM)",
    "ru_maxrss": "ru_maxrss (no /proc/self/status: a figure may include this script's own peak)",
}
# (a) the review as a user runs it
REVIEW = "import sys\nfrom pipelines.cli import main\nmain(['review', sys.argv[1], '--json', sys.argv[2]])\n"
# the interpreter with the reader loaded and nothing read: the base both stand on
BASE = "import pipelines.cli, pipelines.logs.digest, pipelines.logs.reader\n"
# (b) what `review DIR` did before it kept digests: every recording read into one list, on the same base (the
# reader alone peaks below the CLI's imports: "MB a file" above BASE came out negative)
HOLD_ALL = BASE + (
    "import sys\n"
    "from pipelines.logs.reader import find_recordings, read_recording\n"
    "held = [read_recording(p) for p in find_recordings(sys.argv[1])[0]]\n"
)


def record(folder: Path, episodes: int, spec: ControllerSpec, humans: int) -> list[Path]:
    controller = make_controller(spec)
    recorder = McapEpisodeRecorder(folder)
    for k in range(episodes):
        run_episode(controller, seed=k, scenario=SCENARIOS[k % 2], n_humans=humans, observers=(recorder,))
    return sorted(folder.glob("*.mcap"))


def fill(folder: Path, sources: list[Path], files: int) -> None:
    """Copies of ``sources`` until ``folder`` holds ``files`` recordings (names differ, contents repeat)."""
    for i in range(len(list(folder.glob("*.mcap"))), files):
        source = sources[i % len(sources)]
        shutil.copyfile(source, folder / f"copy{i:06d}_{source.name}")


def peak(code: str, *args: str) -> tuple[float, float, str]:
    """Peak resident memory (MB) and wall time (s) of ``code`` run with ``args`` in a fresh process, and where
    the peak was read (a key of ``PEAK_SOURCES``)."""
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", code + PEAK, *args],
        cwd=ROOT,
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=os.environ | {"PYTHONPATH": str(ROOT)},
    )
    read_from, kb = done.stderr.split()[-2:]
    return int(kb) / 1024, time.perf_counter() - t0, read_from


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--files", type=count_in("files", 1), nargs="+", default=[20, 200])
    parser.add_argument("--episodes", type=episode_count, default=4, help="distinct episodes recorded")
    parser.add_argument("--controller", choices=("cmpc", "dmpc"), default="cmpc")
    parser.add_argument("--predictor", type=predictor_name, default="constant_velocity")
    parser.add_argument("--humans", type=human_count, default=7)
    parser.add_argument("--json", type=output_file, help="also write the rows to this file")
    args = parser.parse_args(argv)
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        check_distinct(parser, "--files", args.files)
        if (
            min(args.files) < args.episodes
        ):  # the folder holds every recorded episode: the row would mislabel it
            parser.error(
                f"--files {min(args.files)}: at least --episodes ({args.episodes}) files are reviewed"
            )
        rows = []
        with tempfile.TemporaryDirectory(prefix="review-memory-") as tmp:
            folder = Path(tmp) / "runs"
            folder.mkdir()
            sources = record(
                folder, args.episodes, ControllerSpec(args.controller, args.predictor), args.humans
            )
            size_kb = sum(p.stat().st_size for p in sources) / len(sources) / 1e3
            base_mb, _, read_from = peak(BASE)
            print(f"episodes recorded: {len(sources)}, {size_kb:.0f} KB a file; interpreter {base_mb:.0f} MB")
            print(f"peak memory: {PEAK_SOURCES[read_from]}")
            head = (
                "files",
                "review MB",
                "review s",
                "all held MB",
                "held s",
                "MB a file",
            )  # held, above the interpreter's
            print(" ".join(f"{h:>{w}}" for h, w in zip(head, (6, 10, 9, 12, 7, 10), strict=True)))
            for files in sorted(args.files):  # the folder only grows
                fill(folder, sources, files)
                review_mb, review_s, _ = peak(REVIEW, str(folder), str(Path(tmp) / "r.json"))
                held_mb, held_s, _ = peak(HOLD_ALL, str(folder))
                rows.append(
                    {
                        "files": files,
                        "review_peak_mb": review_mb,
                        "review_s": review_s,
                        "held_peak_mb": held_mb,
                        "held_s": held_s,
                    }
                )
                per_file = (held_mb - base_mb) / files
                print(
                    f"{files:6d} {review_mb:10.0f} {review_s:9.1f} {held_mb:12.0f} {held_s:7.1f} "
                    f"{per_file:10.2f}"
                )
        if args.json:
            report = {"file_kb": size_kb, "interpreter_mb": base_mb, "peak_from": read_from, "rows": rows}
            write_json(args.json, report)
        return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
