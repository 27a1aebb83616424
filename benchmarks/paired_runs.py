"""Sweeps of the same experiment compared on the crowds they share: success, collision and travel time per
method and crowd size, and the paired success changes of each run against the first (exact McNemar).

    .venv/bin/python benchmarks/paired_runs.py none=runs/table2-full cpm=runs/t2-cpm cpm+g=runs/t2-cpm-g

Reads each run's ``episodes.csv`` (written by ``crowdmpc sweep``); an episode is identified by (method, number
of humans, scenario, seed; the method's case ignored: Table II names it "CMPC", the controllers experiment
"cmpc") and by what else decides its crowd, the profile and the number of robots (another profile or team
draws other humans from the seed: crowdsim.scenarios; the ``profile`` column and the ``-rN`` ending the cell
key, blank in a file written before them), and only the episodes every run has are compared. Prints a Markdown
table.
"""

from __future__ import annotations

import argparse
import csv
import re
import sys
from pathlib import Path

from pipelines.errors import PipelineError
from pipelines.experiments.tables import mcnemar_exact

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import run_main  # noqa: E402

Key = tuple[str, int, str, int, str, str]


# The columns of episodes.csv this reads: the episode's identity, then its outcome.
COLUMNS = ("method", "n_humans", "scenario", "seed", "success", "collision", "travel_time")


def load(run: Path) -> dict[Key, dict[str, str]]:
    path = run / "episodes.csv"
    if not path.is_file():
        raise PipelineError(f"{path}: no such file (a `crowdmpc sweep --out` directory has one)")
    with path.open(newline="") as f:
        rows = csv.DictReader(f)
        missing = [name for name in COLUMNS if name not in (rows.fieldnames or ())]
        if missing:
            raise PipelineError(
                f"{path}: no column {', '.join(missing)} (not a `crowdmpc sweep` episodes.csv)"
            )
        episodes = {}
        for r in rows:
            try:
                key = (r["method"].casefold(), int(r["n_humans"]), r["scenario"], int(r["seed"]), *crowd(r))
            except (AttributeError, TypeError, ValueError):  # a short row (None), a number that is none
                raise PipelineError(f"{path}, line {rows.line_num}: not an episode's row") from None
            episodes[key] = r
        return episodes


def crowd(row: dict[str, str]) -> tuple[str, str]:
    """The row's profile and number of robots (the cell key ends in ``-rN``, docs/outputs.md): with the seed,
    the scenario and the humans, what decides the crowd; blank where the file predates the columns."""
    robots = re.search(r"-r(\d+)$", row.get("cell") or "")
    return row.get("profile") or "", robots.group(1) if robots else ""


def flag(value: str) -> bool:
    return value in ("True", "true", "1")


def cell(rows: list[dict[str, str]]) -> str:
    success = [flag(r["success"]) for r in rows]
    travel = [float(r["travel_time"]) for r in rows if flag(r["success"])]
    collision = 100 * sum(flag(r["collision"]) for r in rows) / len(rows)
    mean_travel = f"{sum(travel) / len(travel):.1f}" if travel else "n/a"
    return f"{100 * sum(success) / len(rows):.1f} / {collision:.1f} / {mean_travel}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("runs", nargs="+", metavar="LABEL=DIR", help="two or more sweep output directories")
    args = parser.parse_args(argv)
    directories: dict[str, Path] = {}
    for item in args.runs:
        label, sep, directory = item.partition("=")
        if not sep or not label or not directory:
            parser.error(f"expected LABEL=DIR, got {item!r}")
        if label in directories:  # a second run under the label replaced the first, unsaid
            parser.error(f"label {label!r} is given twice ({directories[label]} and {directory}); one a run")
        directories[label] = Path(directory)
    if len(directories) < 2:
        parser.error("give at least two runs")
    runs = {label: load(directory) for label, directory in directories.items()}
    labels = list(runs)
    shared = set.intersection(*(set(r) for r in runs.values()))
    if not shared:
        raise PipelineError(
            "the runs share no episode (method, humans, scenario, seed, profile, robots: another profile or "
            "number of robots draws other crowds from the same seeds)"
        )
    print(
        "Success % / collision % / travel time s (successes); paired: success wins / losses against",
        labels[0],
    )
    print(
        "| method | humans | "
        + " | ".join(labels)
        + " | "
        + " | ".join(f"{x} paired" for x in labels[1:])
        + " |"
    )
    print("|---" * (2 + 2 * len(labels) - 1) + "|")
    for method, n in sorted({(k[0], k[1]) for k in shared}):
        keys = sorted(k for k in shared if k[:2] == (method, n))
        cells = [cell([runs[label][k] for k in keys]) for label in labels]
        paired = []
        for label in labels[1:]:
            wins = sum(
                flag(runs[label][k]["success"]) and not flag(runs[labels[0]][k]["success"]) for k in keys
            )
            losses = sum(
                flag(runs[labels[0]][k]["success"]) and not flag(runs[label][k]["success"]) for k in keys
            )
            paired.append(f"+{wins} / −{losses} (p = {mcnemar_exact(wins, losses):.2g})")
        name = runs[labels[0]][keys[0]]["method"]  # as the first run spells it
        print(f"| {name} | {n} ({len(keys)}) | " + " | ".join(cells + paired) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
