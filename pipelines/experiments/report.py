"""From per-episode records to what a reader compares with the paper: CSV, a Markdown table, plots.

``write_report`` writes them all into a sweep's directory: cells.csv (a row per cell: the paper's metrics with
their 95% intervals, our safety figures, among them the collision rate between steps, solver figures, the
paper's figures; the robot-robot contact rate, not in the paper) and episodes.csv (a row per episode)
from here, table.md from pipelines.experiments.tables, a plot per outcome from
pipelines.experiments.report_plots (``OUTCOME_vs_humans.png``; at one crowd size ``OUTCOME_vs_robots.png``
where the robots vary, else ``OUTCOME_by_method.png``), min_distance_hist.csv from
pipelines.experiments.safety_report and the safety plots from pipelines.experiments.safety_plots. The cells'
summaries, with their Wilson intervals, are pipelines.experiments.summary's.
"""

from __future__ import annotations

import csv
import itertools
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from crowdsim.metrics import BETWEEN_STEPS, ROBOT_CONTACT
from pipelines.errors import writes_named
from pipelines.experiments import safety_plots
from pipelines.experiments import safety_report as safety
from pipelines.experiments.cells import Experiment
from pipelines.experiments.report_plots import OUTCOMES, PLOT_AXES, plot_filename, plot_outcomes
from pipelines.experiments.summary import CellSummary, Rate, summarize
from pipelines.experiments.tables import markdown_table
from pipelines.experiments.tasks import Cell
from predictors.durable import replace_durably, sync_folder

CELLS_CSV: Final[str] = "cells.csv"
EPISODES_CSV: Final[str] = "episodes.csv"
TABLE_MD: Final[str] = "table.md"
STAGING_PREFIX: Final[str] = ".report-"  # the folder a report is written into before its files are renamed
# How long ago a report's staging folder (STAGING_PREFIX<pid>-...) must have been written last before a
# later report removes it as a killed report's, its pid running nothing here. That pid names a process of one
# machine only: a report on another machine sharing the sweep folder (a job's report on a cluster node while
# `sweep --report-only` runs on the login node) had its folder removed under it ("No such file or
# directory: 'OUT/.report-PID-.../safety_tradeoff.png'"). A report writes into its folder for seconds.
STALE_STAGING_S: Final[float] = 3600.0


def mpc_columns(cells: Sequence[Cell]) -> dict[str, dict[str, Any]]:
    """cells.csv's ``mpc.KEY`` columns: one per [mpc] key some cell overrides (``--set``, ``--vary``, an
    experiment's own), in the order first met, each cell's value as its MPC plans with it (Table I's where the
    cell does not set it, 0 for w_floc without flocking), empty for a controller without the project's MPC;
    none for a sweep of Table I's settings. A d_min study plots ``mpc.d_min`` against ``collision_rate``
    instead of parsing the value out of ``method``."""
    from pipelines.loop.mpc_setup import mpc_config
    from pipelines.loop.spec import MPC_CONTROLLERS

    keys = list(dict.fromkeys(key for c in cells for key, _ in c.spec.mpc_overrides if key != "jit"))
    columns: dict[str, dict[str, Any]] = {}
    for c in cells:
        config = mpc_config(c.spec) if keys and c.spec.controller in MPC_CONTROLLERS else None
        columns[c.key] = {f"mpc.{key}": None if config is None else getattr(config, key) for key in keys}
    return columns


def cell_rows(summaries: Sequence[CellSummary]) -> list[dict[str, Any]]:
    rows = []
    settings = mpc_columns([s.cell for s in summaries])
    for s in summaries:
        row: dict[str, Any] = {
            "method": s.cell.method,
            "n_humans": s.cell.n_humans,
            "n_robots": s.cell.n_robots,
            "controller": s.cell.spec.controller,
            "predictor": s.cell.spec.predictor_name,  # none for orca, straight: as the records and the key
            # orca and straight predict nothing: no flocking term, no coupling (their keys keep the defaults)
            "flocking": s.cell.spec.flocking if s.cell.spec.kind.uses_predictor else None,
            "coupling": s.cell.spec.coupling if s.cell.spec.kind.uses_predictor else None,
            **safety.world_columns(s.cell),
            **settings[s.cell.key],
            "cell": s.cell.key,
            "episodes": s.episodes,
        }
        for name in ("success", "collision", "contact", "discomfort"):
            r: Rate = getattr(s, name)
            lo, hi = r.interval
            row |= {
                f"{name}_count": r.count,
                f"{name}_rate": r.percent,
                f"{name}_ci_lo": lo,
                f"{name}_ci_hi": hi,
            }
        for scenario, r in s.success_by_scenario.items():
            row |= {f"success_rate_{scenario}": r.percent, f"episodes_{scenario}": r.n}
        row |= {
            "travel_time_mean": s.travel_time_mean,
            "travel_time_ci": s.travel_time_ci,
            "min_distance_mean": s.min_distance_mean,
            "min_distance_median": s.min_distance_median,
            **{f"{k}_step_freq": getattr(s, f"{k}_step_freq") for k in safety.STEP_COUNTS},
            **_added_flag_columns(s),
            "step_median_ms": s.step_median_ms,
            "step_p95_ms": s.step_p95_ms,
            "step_mean_ms": s.step_mean_ms,
            "iterations_mean": s.iterations_mean,
            "fallback_step_rate": s.fallback_step_rate,
        }
        row |= {f"paper_{k}": v for k, v in s.paper_row.items()}
        rows.append(row)
    return rows


def _added_flag_columns(s: CellSummary) -> dict[str, Any]:
    """cells.csv's collision and contact rates between steps and robot-robot contact rate (not in the
    paper), as the paper's rates are written: count, %, 95% Wilson interval; empty when some record lacks the
    field."""
    columns: dict[str, Any] = {}
    for name, count in s.added_flag_counts.items():
        rate = s.added_rate(name)
        lo, hi = (None, None) if rate is None else rate.interval
        percent = None if rate is None else rate.percent
        columns |= {f"{name}_count": count, f"{name}_rate": percent, f"{name}_ci_lo": lo, f"{name}_ci_hi": hi}
    return columns


def episode_rows(records: Iterable[dict[str, Any]], cells: Sequence[Cell] = ()) -> Iterator[dict[str, Any]]:
    """A row per episode, by cell (in ``cells``' order), seed and scenario, the plan's order: episodes.jsonl
    holds them in the order the workers finished them, so two identical sweeps gave files that differed.
    ``method`` is the plan's label of the cell, as cells.csv and table.md name it: a record keeps the label
    of the run that recorded it, so a cell resumed under another one (a plain sweep's "CMPC", extended by
    ``--vary``'s "CMPC horizon=4") read as two methods. Made as they are written: a list of them all was
    0.85 KB an episode beside the records (85 MB at 100,000 episodes, benchmarks/sweep_log_scale.py)."""
    place = {c.key: i for i, c in enumerate(cells)}
    label = {c.key: c.method for c in cells}
    for r in sorted(records, key=lambda r: (place.get(r["cell"], len(place)), r["seed"], str(r["scenario"]))):
        yield episode_row(r, label.get(r["cell"], r["method"]))


def episode_row(r: dict[str, Any], method: str) -> dict[str, Any]:
    """episodes.csv's row of record ``r``, of the cell the plan labels ``method``."""
    m, s = r["metrics"], r["solver"]
    return {
        "key": r["key"],
        "method": method,
        "n_humans": r["n_humans"],
        "n_robots": r.get("n_robots"),  # a hand-made or foreign line without it: an empty cell, not a refusal
        "scenario": r["scenario"],
        "seed": r["seed"],
        "success": m["success"],
        "travel_time": m["travel_time"],
        "collision": m["collision"],
        "contact": m["contact"],
        "discomfort": m["discomfort"],
        "min_distance": m["min_distance"],
        "n_steps": m["n_steps"],
        # Absent from records written before them: empty cells, not a failed report. discomfort_steps, which
        # cells.csv's discomfort_step_freq counts, beside them (a record of any version has it; still read
        # with get, as the others).
        **{k: m.get(k) for k in ("collision_steps", "contact_steps", "discomfort_steps")},
        **{k: m.get(k) for k in BETWEEN_STEPS},
        **{k: m.get(k) for k in ROBOT_CONTACT},
        **{k: r.get(k) for k in ("margins", "profile", "visibility", "sensor_range", "sensor_tracks")},
        "step_median_ms": s["median_ms"],
        "step_p95_ms": s["p95_ms"],
        "step_max_ms": s["max_ms"],
        "mean_iterations": s["mean_iterations"],
        "fallback_steps": s["fallback_steps"],
        "wall_s": r["wall_s"],
        "cell": r["cell"],
    }


def write_csv(path: Path, rows: Iterable[dict[str, Any]]) -> None:
    """``rows`` as CSV, the first row's keys the header (an empty file for no rows); None and NaN empty."""
    rows = iter(rows)
    with open(path, "w", encoding="utf-8", newline="") as f:
        first = next(rows, None)
        if first is None:
            return
        writer = csv.DictWriter(f, fieldnames=list(first))
        writer.writeheader()
        writer.writerows(
            {k: ("" if v is None or v != v else v) for k, v in row.items()}
            for row in itertools.chain([first], rows)
        )


@dataclass(frozen=True)
class Report:
    markdown: str
    files: tuple[Path, ...]


def write_report(
    out: Path, experiment: Experiment, cells: Sequence[Cell], records: Sequence[dict[str, Any]]
) -> Report:
    """cells.csv, episodes.csv, table.md, min_distance_hist.csv and the plots in ``out``; ``records`` are
    those of ``cells``. Each file is written whole into a staging folder in ``out`` and then renamed over its
    old version, so that an interrupted report (a second Ctrl-C, a kill) leaves every file complete, the
    previous report's or this one's, never half written; a killed report's staging folder is removed by the
    next report."""
    keys = {c.key for c in cells}
    records = [r for r in records if r["cell"] in keys]
    return write_report_of(
        out, experiment, summarize(experiment, cells, records), episode_rows(records, cells)
    )


def write_report_of(
    out: Path,
    experiment: Experiment,
    summaries: Sequence[CellSummary],
    rows: Iterable[dict[str, Any]],
    note: str = "",
) -> Report:
    """``write_report`` of the cells' ``summaries`` and episodes.csv's ``rows`` (``episode_row``'s, in the
    plan's order): a report that reads a sweep's log once more for the rows rather than holding its records
    (pipelines.commands.sweep_log_read). ``note``: a paragraph after table.md's table."""
    from pipelines.experiments.worker import remove_stale_scratch

    out = Path(out)
    markdown = markdown_table(experiment, summaries) + (f"\n{note}\n" if note else "")
    # a killed report's: not one another process writes now, here or on another machine
    remove_stale_scratch(out, STAGING_PREFIX, older_than_s=STALE_STAGING_S)
    staging = Path(tempfile.mkdtemp(prefix=f"{STAGING_PREFIX}{os.getpid()}-", dir=out))
    # a full disk's error names the report's folder: the files renamed before it are this report's, the
    # others the earlier one's, each whole
    with writes_named(out):
        try:
            written = _write_staged(staging, experiment, summaries, rows, markdown)
            for name in written:  # the folder synced once, after the last rename: not once a file
                replace_durably(staging / name, out / name, sync_target_folder=False)
            for name in sorted(report_plot_names() - set(written)):
                (out / name).unlink(missing_ok=True)  # an earlier report's, of cells this one does not have
            sync_folder(out)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    return Report(markdown, tuple(out / name for name in written))


def _write_staged(
    staging: Path,
    experiment: Experiment,
    summaries: Sequence[CellSummary],
    rows: Iterable[dict[str, Any]],
    markdown: str,
) -> list[str]:
    """Every file of the report into ``staging``; their names."""
    write_csv(staging / CELLS_CSV, cell_rows(summaries))
    write_csv(staging / EPISODES_CSV, rows)
    (staging / TABLE_MD).write_text(markdown, encoding="utf-8")
    write_csv(staging / safety.MIN_DISTANCE_HIST_CSV, safety.min_distance_hist_rows(summaries))
    written = [CELLS_CSV, EPISODES_CSV, TABLE_MD, safety.MIN_DISTANCE_HIST_CSV]
    if summaries:
        plots = plot_outcomes(experiment, summaries, staging)
        plots += safety_plots.plot_safety(experiment, summaries, staging)
        written += [plot.name for plot in plots]
    return written


def report_plot_names() -> set[str]:
    """Every plot a report may write: a report at other crowd sizes leaves its predecessor's none of its own
    (five *_vs_humans.png of 5 and 6 humans beside a table of 5 contradicted it)."""
    names = {plot_filename(o.name, axis) for o in OUTCOMES for axis in PLOT_AXES}
    return names | {safety.MIN_DISTANCE_HIST_PNG, safety.SAFETY_TRADEOFF_PNG}
