"""From per-episode records to what a reader compares with the paper: CSV, a Markdown table, plots.

Rates come with 95% Wilson score intervals (Wilson 1927; the interval that stays inside [0, 100] % and keeps
its coverage for rates near 0 or 100 % and for small samples, where the normal approximation fails: 0 of 200
collisions gives [0, 1.9] %, not [0, 0]). Travel time is the mean over successful episodes with a normal 95%
interval of the mean (1.96 standard errors). The Markdown table is laid out like the paper's Tables II/III:
one column per method and number of pedestrians, the four metrics as rows, the paper's figure under each
of ours, and the better method of each group in bold (as the paper prints it). Per-step frequencies, the
histogram of closest approaches and the success / collision trade-off come from pipelines.safety_report.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np

from pipelines.errors import PipelineError
from pipelines.experiments import safety_report as safety
from pipelines.experiments.cells import SCENARIOS, Cell, Experiment, PaperFigures, predictor_of

Z95: Final[float] = 1.959963984540054  # two-sided 95% standard normal quantile
CELLS_CSV: Final[str] = "cells.csv"
EPISODES_CSV: Final[str] = "episodes.csv"
TABLE_MD: Final[str] = "table.md"
SUCCESS_PNG: Final[str] = "success_vs_humans.png"
TRAVEL_TIME_PNG: Final[str] = "travel_time_vs_humans.png"


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of a binomial proportion, as fractions in [0, 1]; (nan, nan) when n = 0."""
    if n < 0 or not 0 <= successes <= n:
        raise PipelineError(f"wilson_interval needs 0 <= successes <= n, got {successes} of {n}")
    if n == 0:
        return math.nan, math.nan
    p = successes / n
    denominator = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denominator
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass(frozen=True)
class Rate:
    count: int
    n: int

    @property
    def percent(self) -> float:
        return 100.0 * self.count / self.n if self.n else math.nan

    @property
    def interval(self) -> tuple[float, float]:
        """95% Wilson interval in %."""
        lo, hi = wilson_interval(self.count, self.n)
        return 100.0 * lo, 100.0 * hi


@dataclass(frozen=True)
class CellSummary:
    """One cell's episodes, reduced to the paper's metrics and our solver figures."""

    cell: Cell
    episodes: int
    success: Rate
    collision: Rate
    contact: Rate
    discomfort: Rate
    success_by_scenario: dict[str, Rate]
    successes: dict[tuple[str, int], bool]  # (scenario, seed) -> success: pairs episodes across cells
    travel_time_mean: float  # s, over successful episodes (nan if none)
    travel_time_ci: float  # s, half width of the 95% interval of the mean (nan with < 2 successes)
    min_distance_mean: float  # m, robot-human
    min_distance_median: float  # m, robot-human
    min_distances: tuple[float, ...]  # m, each episode's minimum robot-human distance (inf: no human)
    # % of recorded states (rows 0..T) with the condition, over the cell; nan when some record lacks the count
    collision_step_freq: float
    contact_step_freq: float
    discomfort_step_freq: float
    step_median_ms: float  # median over episodes of the per-episode median control step
    step_p95_ms: float  # 95th percentile over episodes of the per-episode p95
    step_mean_ms: float  # all control-step time / all steps
    iterations_mean: float  # IBR iterations per control step
    fallback_step_rate: float  # % of control steps that fell back
    paper: PaperFigures | None

    @property
    def paper_row(self) -> dict[str, float | None]:
        return (
            asdict(self.paper)
            if self.paper
            else dict.fromkeys(("success", "travel_time", "collision", "discomfort"))
        )


def _mean(values: Sequence[float]) -> float:
    return float(np.mean(values)) if len(values) else math.nan


def _half_width(values: Sequence[float]) -> float:
    """Half width of the normal 95% interval of the mean (nan with fewer than two values)."""
    if len(values) < 2:
        return math.nan
    return Z95 * float(np.std(values, ddof=1)) / math.sqrt(len(values))


def summarize_cell(cell: Cell, records: Sequence[dict[str, Any]], paper: PaperFigures | None) -> CellSummary:
    n = len(records)
    metrics = [r["metrics"] for r in records]

    def rate(name: str, rows: Sequence[dict[str, Any]] = metrics) -> Rate:
        return Rate(sum(bool(m[name]) for m in rows), len(rows))

    times = [m["travel_time"] for m in metrics if m["success"] and m["travel_time"] is not None]
    solver = [r["solver"] for r in records]
    steps = sum(s["steps"] for s in solver)
    medians = [s["median_ms"] for s in solver if s["median_ms"] is not None]
    p95s = [s["p95_ms"] for s in solver if s["p95_ms"] is not None]
    iterations = [s["mean_iterations"] for s in solver if s["mean_iterations"] is not None]
    return CellSummary(
        cell=cell,
        episodes=n,
        success=rate("success"),
        collision=rate("collision"),
        contact=rate("contact"),
        discomfort=rate("discomfort"),
        successes={(r["scenario"], r["seed"]): bool(r["metrics"]["success"]) for r in records},
        success_by_scenario={
            s: rate("success", [r["metrics"] for r in records if r["scenario"] == s]) for s in SCENARIOS
        },
        travel_time_mean=_mean(times),
        travel_time_ci=_half_width(times),
        min_distance_mean=_mean([m["min_distance"] for m in metrics if m["min_distance"] is not None]),
        **safety.safety_figures(metrics),
        step_median_ms=float(np.median(medians)) if medians else math.nan,
        step_p95_ms=float(np.percentile(p95s, 95)) if p95s else math.nan,
        step_mean_ms=sum(s["total_ms"] for s in solver) / steps if steps else math.nan,
        iterations_mean=_mean(iterations),
        fallback_step_rate=100.0 * sum(s["fallback_steps"] for s in solver) / steps if steps else math.nan,
        paper=paper,
    )


def summarize(
    experiment: Experiment, cells: Sequence[Cell], records: Iterable[dict[str, Any]]
) -> list[CellSummary]:
    """One summary per cell that has records, in table order."""
    by_cell: dict[str, list[dict[str, Any]]] = {}
    for record in records:
        by_cell.setdefault(record["cell"], []).append(record)
    return [
        summarize_cell(cell, by_cell[cell.key], experiment.paper.get((cell.method, cell.n_humans)))
        for cell in cells
        if by_cell.get(cell.key)
    ]


# ----------------------------------------------------------------------------------------------------------
# CSV
# ----------------------------------------------------------------------------------------------------------


def cell_rows(summaries: Sequence[CellSummary]) -> list[dict[str, Any]]:
    rows = []
    for s in summaries:
        row: dict[str, Any] = {
            "method": s.cell.method,
            "n_humans": s.cell.n_humans,
            "n_robots": s.cell.n_robots,
            "controller": s.cell.spec.controller,
            "predictor": s.cell.spec.predictor,
            "flocking": s.cell.spec.flocking,
            "coupling": s.cell.spec.coupling,
            **safety.world_columns(s.cell),
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
            "step_median_ms": s.step_median_ms,
            "step_p95_ms": s.step_p95_ms,
            "step_mean_ms": s.step_mean_ms,
            "iterations_mean": s.iterations_mean,
            "fallback_step_rate": s.fallback_step_rate,
        }
        row |= {f"paper_{k}": v for k, v in s.paper_row.items()}
        rows.append(row)
    return rows


def episode_rows(records: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    for r in records:
        m, s = r["metrics"], r["solver"]
        rows.append(
            {
                "key": r["key"],
                "method": r["method"],
                "n_humans": r["n_humans"],
                "scenario": r["scenario"],
                "seed": r["seed"],
                "success": m["success"],
                "travel_time": m["travel_time"],
                "collision": m["collision"],
                "contact": m["contact"],
                "discomfort": m["discomfort"],
                "min_distance": m["min_distance"],
                "n_steps": m["n_steps"],
                # Absent from records written before them: empty cells, not a failed report.
                **{k: m.get(k) for k in ("collision_steps", "contact_steps")},
                **{k: r.get(k) for k in ("margins", "profile", "visibility")},
                "step_median_ms": s["median_ms"],
                "step_p95_ms": s["p95_ms"],
                "step_max_ms": s["max_ms"],
                "mean_iterations": s["mean_iterations"],
                "fallback_steps": s["fallback_steps"],
                "wall_s": r["wall_s"],
                "cell": r["cell"],
            }
        )
    return rows


def write_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    with open(path, "w", newline="") as f:
        if not rows:
            return
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows({k: ("" if v is None or v != v else v) for k, v in row.items()} for row in rows)


# ----------------------------------------------------------------------------------------------------------
# Markdown
# ----------------------------------------------------------------------------------------------------------


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided exact McNemar test: the p-value of ``b`` vs ``c`` discordant pairs under a fair coin."""
    n = b + c
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, k) for k in range(min(b, c) + 1)) / 2.0**n
    return min(1.0, 2.0 * tail)


def paired_success(reference: CellSummary, other: CellSummary) -> tuple[int, int, float]:
    """On the crowds both cells ran: (other succeeded where the reference failed, the reverse, McNemar p)."""
    shared = reference.successes.keys() & other.successes.keys()
    gained = sum(other.successes[k] and not reference.successes[k] for k in shared)
    lost = sum(reference.successes[k] and not other.successes[k] for k in shared)
    return gained, lost, mcnemar_exact(gained, lost)


def _fmt(x: float | None, digits: int = 1) -> str:
    return "—" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def _rate_cell(r: Rate) -> str:
    lo, hi = r.interval
    return f"{_fmt(r.percent)} [{_fmt(lo)}, {_fmt(hi)}]" if r.n else "—"


def _best(values: Sequence[float], higher_is_better: bool) -> set[int]:
    """Indices of the best value (as printed, one decimal) in a group; none when every method ties or the
    group has one member, as the paper leaves ties unmarked."""
    finite = [(i, round(v, 1)) for i, v in enumerate(values) if not math.isnan(v)]
    if len(values) < 2 or not finite:
        return set()
    best = (max if higher_is_better else min)(v for _, v in finite)
    winners = {i for i, v in finite if v == best}
    return winners if len(winners) < len(values) else set()


def _table_notes(experiment: Experiment, columns: Sequence[CellSummary], world_line: str) -> str:
    """The paragraph above the table: how many episodes, which predictors and conventions, how to read it."""
    predictors = sorted({predictor_of(s.cell.spec) or "none" for s in columns})
    counts = sorted({s.episodes for s in columns})
    per_cell = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}–{counts[-1]}"
    notes = [
        f"## {experiment.title}",
        "",
        f"Ours: {per_cell} episodes per cell, "
        "half circle and half perpendicular crossing, the same seeds in every cell; "
        f"predictor{'s' if len(predictors) > 1 else ''} {', '.join(predictors)}. Rates with their 95% Wilson "
        "interval in brackets; travel time over successful episodes ± the 95% interval of its mean. "
        "Bold: the better method at each number of pedestrians. Paired: episodes (same crowd) this method "
        "succeeded and the first one failed / the reverse, with the exact McNemar p-value.",
        world_line,
    ]
    if any(s.paper for s in columns):
        notes.append(f"Paper ('paper' rows): 1000 episodes per cell (500 + 500), {experiment.paper_source}.")
    else:
        notes.append("The paper has no such table.")
    return "\n".join(notes)


def markdown_table(experiment: Experiment, summaries: Sequence[CellSummary]) -> str:
    """The paper's layout: a column per (number of pedestrians, method), metrics as rows, paper under ours."""
    if not summaries:
        return f"## {experiment.title}\n\nNo episodes recorded yet.\n"
    groups: dict[int, list[CellSummary]] = {}
    for s in summaries:
        groups.setdefault(s.cell.n_humans, []).append(s)
    columns = [s for n in sorted(groups) for s in groups[n]]
    has_paper = any(s.paper for s in columns)

    def bolded(texts: list[str], values: list[float], higher_is_better: bool) -> list[str]:
        out = []
        for n in sorted(groups):
            idx = [columns.index(s) for s in groups[n]]
            best = _best([values[i] for i in idx], higher_is_better)
            out += [f"**{texts[i]}**" if j in best else texts[i] for j, i in enumerate(idx)]
        return out

    def paper_values(name: str) -> list[float]:
        return [getattr(s.paper, name) if s.paper else math.nan for s in columns]

    lines = [
        "| Metrics \\ Methods | " + " | ".join(s.cell.method for s in columns) + " |",
        "|---|" + "---|" * len(columns),
        "| Numbers of pedestrians | " + " | ".join(str(s.cell.n_humans) for s in columns) + " |",
    ]
    world_line, worlds = safety.world_note([s.cell for s in columns])
    if worlds:
        lines.append("| Margins / profile / visibility | " + " | ".join(worlds) + " |")

    def add(label: str, texts: list[str]) -> None:
        lines.append(f"| {label} | " + " | ".join(texts) + " |")

    metric_rows = (
        ("Success rate (%)", "success", True),
        ("Average travel time (s)", "travel_time", False),
        ("Collision rate (%)", "collision", False),
        ("Discomfort rate (%)", "discomfort", False),
    )
    for label, name, higher in metric_rows:
        if name == "travel_time":
            values = [s.travel_time_mean for s in columns]
            texts = [
                f"{_fmt(s.travel_time_mean)} ± {_fmt(s.travel_time_ci)}"
                if s.travel_time_ci == s.travel_time_ci
                else _fmt(s.travel_time_mean)
                for s in columns
            ]
        else:
            rates: list[Rate] = [getattr(s, name) for s in columns]
            values = [r.percent for r in rates]
            texts = [_rate_cell(r) for r in rates]
        add(label, bolded(texts, values, higher))
        if has_paper:
            pv = paper_values(name)
            add("&nbsp;&nbsp;paper", bolded([_fmt(v) for v in pv], pv, higher))
    add("Contact rate (%) (< 0.6 m)", [_rate_cell(s.contact) for s in columns])
    add("Collision per step (%)", [_fmt(s.collision_step_freq, 2) for s in columns])
    add("Min robot-human distance, median (m)", [_fmt(s.min_distance_median, 2) for s in columns])
    add(
        "Success circle / perpendicular (%)",
        [" / ".join(_fmt(s.success_by_scenario[sc].percent, 0) for sc in SCENARIOS) for s in columns],
    )
    paired = []
    for s in columns:
        reference = groups[s.cell.n_humans][0]
        if s is reference:
            paired.append("reference" if len(groups[s.cell.n_humans]) > 1 else "—")
        else:
            gained, lost, p = paired_success(reference, s)
            paired.append(f"+{gained} / −{lost} (p = {p:.2g})")
    add("Success, paired with the group's first method", paired)
    add("Episodes", [str(s.episodes) for s in columns])
    add(
        "Control step median / p95 (ms)",
        [f"{_fmt(s.step_median_ms, 2)} / {_fmt(s.step_p95_ms, 2)}" for s in columns],
    )
    add("IBR iterations per step (mean)", [_fmt(s.iterations_mean, 2) for s in columns])
    add("Fallback steps (%)", [_fmt(s.fallback_step_rate, 2) for s in columns])

    return _table_notes(experiment, columns, world_line) + "\n\n" + "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------------------------
# Plots
# ----------------------------------------------------------------------------------------------------------


def plot_vs_humans(experiment: Experiment, summaries: Sequence[CellSummary], out: Path) -> list[Path]:
    """Success rate and travel time against the number of humans, one line per method (bars when the
    experiment has a single crowd size), our 95% intervals as error bars and the paper's figures dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = [m for m in experiment.method_labels if any(s.cell.method == m for s in summaries)]
    humans = sorted({s.cell.n_humans for s in summaries})
    written = []
    panels = (
        ("success", "Success rate (%)", SUCCESS_PNG),
        ("travel_time", "Average travel time (s)", TRAVEL_TIME_PNG),
    )
    for name, ylabel, filename in panels:
        fig, ax = plt.subplots(figsize=(6.4, 4.2), layout="constrained")
        for k, method in enumerate(methods):
            cells = sorted((s for s in summaries if s.cell.method == method), key=lambda s: s.cell.n_humans)
            x = np.array([s.cell.n_humans for s in cells], dtype=float)
            if name == "success":
                y = np.array([s.success.percent for s in cells])
                ci = np.array([s.success.interval for s in cells]).T
                err = np.abs(ci - y)
            else:
                y = np.array([s.travel_time_mean for s in cells])
                err = np.array([s.travel_time_ci for s in cells])
            color = f"C{k}"
            if len(humans) == 1:
                ax.bar(
                    k, y[0], yerr=None if np.isnan(err).all() else err.reshape(-1, 1), color=color, capsize=4
                )
            else:
                ax.errorbar(x, y, yerr=err, marker="o", capsize=3, color=color, label=f"{method} (ours)")
            paper = [(s.cell.n_humans, getattr(s.paper, name)) for s in cells if s.paper]
            if paper:
                px, py = zip(*paper, strict=True)
                ax.plot(px, py, ls="--", marker="s", mfc="none", color=color, label=f"{method} (paper)")
        if len(humans) == 1:
            ax.set_xticks(range(len(methods)), methods, rotation=30, ha="right")
            ax.set_xlabel(f"method ({humans[0]} humans)")
        else:
            ax.set_xticks(humans)
            ax.set_xlabel("number of humans")
            ax.legend(fontsize="small")
        ax.set_ylabel(ylabel)
        ax.set_title(experiment.title, fontsize="medium")
        ax.grid(alpha=0.3)
        path = out / filename
        fig.savefig(path, dpi=120)
        plt.close(fig)
        written.append(path)
    return written


# ----------------------------------------------------------------------------------------------------------
# Everything at once
# ----------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Report:
    markdown: str
    files: tuple[Path, ...]


def write_report(
    out: Path, experiment: Experiment, cells: Sequence[Cell], records: Sequence[dict[str, Any]]
) -> Report:
    """cells.csv, episodes.csv, table.md, min_distance_hist.csv and the plots in ``out``; ``records`` are
    those of ``cells``."""
    out = Path(out)
    keys = {c.key for c in cells}
    records = [r for r in records if r["cell"] in keys]
    summaries = summarize(experiment, cells, records)
    write_csv(out / CELLS_CSV, cell_rows(summaries))
    write_csv(out / EPISODES_CSV, episode_rows(records))
    markdown = markdown_table(experiment, summaries)
    (out / TABLE_MD).write_text(markdown)
    write_csv(out / safety.MIN_DISTANCE_HIST_CSV, safety.min_distance_hist_rows(summaries))
    files = [out / CELLS_CSV, out / EPISODES_CSV, out / TABLE_MD, out / safety.MIN_DISTANCE_HIST_CSV]
    if summaries:
        files += plot_vs_humans(experiment, summaries, out) + safety.plot_safety(experiment, summaries, out)
    return Report(markdown, tuple(files))
