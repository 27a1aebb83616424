"""A cell's episode records reduced to the paper's metrics, with their confidence intervals.

Rates come with 95% Wilson score intervals (Wilson 1927; the interval that stays inside [0, 100] % and keeps
its coverage for rates near 0 or 100 % and for small samples, where the normal approximation fails: 0 of 200
collisions gives [0, 1.9] %, not [0, 0]). Travel time is the mean over successful episodes with the 95%
interval of the mean from Student's t (n - 1 degrees of freedom: 12.7 standard errors for 2 successes, 2.78
for 5, 1.96 in the limit; a normal interval would be far too narrow for a small sweep). The safety fields
(per-step frequencies, closest approaches) come from pipelines.experiments.safety_report. Every part of the
report (pipelines.experiments.report, .tables, .report_plots) reads these summaries.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Final

import numpy as np

from crowdsim.world import PAPER_ROBOTS
from pipelines.errors import PipelineError
from pipelines.experiments import safety_report as safety
from pipelines.experiments.cell_columns import CellColumns, calibration_texts
from pipelines.experiments.cells import Experiment, PaperFigures
from pipelines.experiments.tasks import SCENARIOS, Cell

Z95: Final[float] = 1.959963984540054  # two-sided 95% standard normal quantile


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
    # At 0 of n (n of n) the bound is exactly 0 (1), centre and half width being the same number computed
    # two ways: their difference left 5.6e-17 at 0 of 3 and 50, which cells.csv wrote as 5.55e-15 %.
    lo = 0.0 if successes == 0 else max(0.0, centre - half)
    hi = 1.0 if successes == n else min(1.0, centre + half)
    return lo, hi


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
    robot_contact_step_freq: float  # two robots touching (crowdsim.metrics), not a metric of the paper
    # episodes in which a flag added after the first records held, by its name (crowdsim.metrics.ADDED_FLAGS:
    # the closest approach within a step a collision, resp. contact; robots touching each other); None when
    # some record predates the field
    added_flag_counts: dict[str, int | None]
    # Of the episodes' own statistics, not pooled over all steps as `simulate` and `review` print them: a
    # record keeps each episode's median and p95, not its steps. The table's label says which.
    step_median_ms: float  # median over episodes of the per-episode median control step
    step_p95_ms: float  # 95th percentile over episodes of the per-episode p95
    step_mean_ms: float  # all control-step time / all steps
    # nan when no control step ran a solver (``runs_solver`` False: ORCA, straight line)
    iterations_mean: float  # IBR iterations per control step: all iterations / all steps
    fallback_step_rate: float  # % of control steps that fell back
    runs_solver: bool  # some control step iterated (IBR iterations > 0); the baselines report 0 throughout
    calibrations: tuple[str, ...]  # where calibrated margins came from (cell_columns.calibration_texts)
    paper: PaperFigures | None

    def added_rate(self, name: str) -> Rate | None:
        """The rate of flag ``name`` added after the first records (crowdsim.metrics.ADDED_FLAGS) over the
        cell's episodes; None when some record of the cell predates it (table.md's "—", cells.csv's empty
        columns, the plots' "not recorded")."""
        count = self.added_flag_counts.get(name)
        return None if count is None else Rate(count, self.episodes)

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
    """Half width of the 95% interval of the mean, Student's t (nan with fewer than two values)."""
    if len(values) < 2:
        return math.nan
    return t95(len(values) - 1) * float(np.std(values, ddof=1)) / math.sqrt(len(values))


@functools.lru_cache(maxsize=256)
def t95(dof: int) -> float:
    """The two-sided 95% quantile of Student's t with ``dof`` degrees of freedom (t95(1) = 12.706,
    t95(4) = 2.776). Exact for dof <= 1000 (bisection on the closed-form P(|T| < t), Abramowitz and Stegun
    26.7.3-4); beyond, the Cornish-Fisher expansion about Z95, whose error there is below 3e-9."""
    if dof < 1:
        raise PipelineError(f"t95 needs at least one degree of freedom, got {dof}")
    if dof > 1000:
        z = Z95
        return z + (z**3 + z) / (4 * dof) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * dof**2)
    low, high = Z95, 20.0  # t95(1) = 12.71 is the largest
    for _ in range(60):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if _t_central(middle, dof) < 0.95 else (low, middle)
    return 0.5 * (low + high)


def _t_central(t: float, dof: int) -> float:
    """P(|T| < t) for Student's t with an integer ``dof`` >= 1 (Abramowitz and Stegun 26.7.3-4)."""
    theta = math.atan(t / math.sqrt(dof))
    c2, sin = math.cos(theta) ** 2, math.sin(theta)
    if dof % 2 == 0:  # sin(theta) (1 + 1/2 c^2 + 1.3/(2.4) c^4 + ... up to c^(dof-2))
        term = total = 1.0
        for j in range(1, dof // 2):
            term *= (2 * j - 1) / (2 * j) * c2
            total += term
        return sin * total
    total = 0.0  # 2/pi (theta + sin(theta) (c + 2/3 c^3 + 2.4/(3.5) c^5 + ... up to c^(dof-2)))
    term = math.sqrt(c2)
    for j in range(1, (dof - 1) // 2 + 1):
        total += term
        term *= (2 * j) / (2 * j + 1) * c2
    return 2.0 / math.pi * (theta + sin * total)


def summarize_cell(
    cell: Cell,
    records: Sequence[dict[str, Any]],
    paper: PaperFigures | None,
    calibrations: Iterable[str] | None = None,
) -> CellSummary:
    """``calibrations``: where the records' calibrated margins came from (``cell_columns.calibration_texts``;
    None: read from ``records``)."""
    # in the plan's order (seed, scenario), not the order the workers finished: a resumed sweep's cells.csv
    # differed from an uninterrupted one's in the last digits of its means
    records = sorted(records, key=lambda r: (r["seed"], str(r["scenario"])))
    n = len(records)
    metrics = [r["metrics"] for r in records]

    def rate(name: str, rows: Sequence[dict[str, Any]] = metrics) -> Rate:
        return Rate(sum(bool(m[name]) for m in rows), len(rows))

    times = [m["travel_time"] for m in metrics if m["success"] and m["travel_time"] is not None]
    solver = [r["solver"] for r in records]
    steps = sum(s["steps"] for s in solver)
    medians = [s["median_ms"] for s in solver if s["median_ms"] is not None]
    p95s = [s["p95_ms"] for s in solver if s["p95_ms"] is not None]
    # (episode's mean, its steps): weighed by its steps, as `simulate` pools them, not a mean of the means
    iterations = [(s["mean_iterations"], s["steps"]) for s in solver if s["mean_iterations"] is not None]
    runs_solver = any(i > 0 for i, _ in iterations)
    iterated_steps = sum(steps for _, steps in iterations)
    fallbacks = sum(s["fallback_steps"] for s in solver)
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
        iterations_mean=(
            sum(i * steps for i, steps in iterations) / iterated_steps if runs_solver else math.nan
        ),
        # a controller without a solver has nothing to fall back from (unless it says it did)
        fallback_step_rate=100.0 * fallbacks / steps if steps and (runs_solver or fallbacks) else math.nan,
        runs_solver=runs_solver,
        calibrations=tuple(sorted(calibration_texts(records) if calibrations is None else calibrations)),
        paper=paper,
    )


def summarize(
    experiment: Experiment, cells: Sequence[Cell], records: Iterable[dict[str, Any]]
) -> list[CellSummary]:
    """One summary per cell that has records, in table order; the paper's figures beside the cells it has
    figures for (``paper_figures``)."""
    by_cell: dict[str, list[dict[str, Any]]] = {}
    for record in records:
        by_cell.setdefault(record["cell"], []).append(record)
    return [
        summarize_cell(cell, by_cell[cell.key], paper_figures(experiment, cell))
        for cell in cells
        if by_cell.get(cell.key)
    ]


def summarize_columns(
    experiment: Experiment, cells: Sequence[Cell], columns: Mapping[str, CellColumns]
) -> list[CellSummary]:
    """``summarize`` of records held as columns, by cell key (pipelines.experiments.cell_columns): a cell's
    episodes are made records one cell at a time, and only of the fields the summary reads."""
    return [
        summarize_cell(
            cell,
            columns[cell.key].episodes(),
            paper_figures(experiment, cell),
            columns[cell.key].calibrations,
        )
        for cell in cells
        if cell.key in columns and len(columns[cell.key])
    ]


def paper_figures(experiment: Experiment, cell: Cell) -> PaperFigures | None:
    """The paper's figures for ``cell``: its method at its number of humans, with the paper's team of
    robots (its tables are all of PAPER_ROBOTS robots; another team's figures are not comparable)."""
    if cell.n_robots != PAPER_ROBOTS:
        return None
    return experiment.paper.get((cell.method, cell.n_humans))
