"""The report's plots, one per outcome: success, travel time, collision, contact and discomfort, ours beside
the paper's, what a control step costs (the median, bars up to the p95), and, where some cell ran more than
one robot and recorded it, robots touching each other (``robot_contact``, not a metric of the paper).

An experiment over several crowd sizes (Tables II and III) gets ``OUTCOME_vs_humans.png``: the number of
humans on the x axis, a line per method. One at one crowd size whose columns vary the number of robots
(``--vary scenario.robots``) gets ``OUTCOME_vs_robots.png``: the number of robots on the x axis, a line per
method the columns share. Any other at one crowd size (the predictor swap, coupling, safety, ...) gets
``OUTCOME_by_method.png``: a bar per method. Our 95% intervals are the error bars (Wilson
for the rates, Student's t for the mean travel time: pipelines.experiments.summary), and each plot's title
says which; the paper's figures are open squares (dashed lines across crowd sizes). The safety plots
(closest approaches, the success / collision trade-off) are pipelines.experiments.safety_plots', of
safety_report's figures.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np

from crowdsim.metrics import ADDED_FLAGS, COLLISION_DISTANCE
from pipelines.experiments.cells import Experiment
from pipelines.experiments.plot_style import method_style, settings_line, wrap_title
from pipelines.experiments.summary import CellSummary, Rate
from predictors.text_table import counted

ROBOT_CONTACT_FLAG: Final[str] = "robot_contact"  # crowdsim.metrics' flag: two robots touched in the episode


@dataclass(frozen=True)
class Outcome:
    """One plotted outcome: a ``CellSummary`` field, also the file's stem and, where the paper reports it, a
    ``PaperFigures`` field."""

    name: str
    ylabel: str
    meaning: str  # a line under the title saying what counts
    interval: str = "Wilson interval"  # what the error bars are: the 95% interval summary.py gives
    bars: str | None = None  # the title's line on the bars where they are no 95% interval of ours
    missing: str = "no success"  # what a method without any value has (the legend's words)
    no_bars: str = "fewer than two successes"  # why a plot has no error bar at all (the title's words)


OUTCOMES: Final[tuple[Outcome, ...]] = (
    Outcome("success", "Success rate (%)", "the robots reach their goals within the time limit"),
    Outcome(
        "travel_time",
        "Average travel time (s)",
        "mean over successful episodes",
        interval="Student's t interval of the mean",
    ),
    Outcome(
        "collision",
        "Collision rate (%)",
        f"a robot closer than {COLLISION_DISTANCE:g} m to a human (personal-space violation)",
    ),
    Outcome("contact", "Contact rate (%)", "a robot touching a human (closer than the sum of their radii)"),
    Outcome("discomfort", "Discomfort rate (%)", "a robot's projected path crossing a human's"),
    # robot-robot: plotted only where some cell ran several robots and recorded it (plotted_outcomes)
    Outcome(
        ROBOT_CONTACT_FLAG,
        "Robot-robot contact rate (%), not in the paper",
        "two robots touching (closer than the sum of their radii); not in the paper",
        missing="not recorded",
        no_bars="not recorded",
    ),
    # what a control step costs (prediction, solves, bookkeeping): the scale study's figure against robots
    Outcome(
        "control_step",
        "Control step (ms)",
        "median of the episodes' median steps",
        bars="bars up to the p95 of the episodes' p95 steps; the period is 400 ms",
        missing="not recorded",
    ),
)


def plotted_outcomes(summaries: Sequence[CellSummary]) -> tuple[Outcome, ...]:
    """``OUTCOMES`` a report of ``summaries`` plots: robot-robot contact only where a cell ran more than one
    robot and its records hold the flag (those written before it do not): with one robot it cannot
    happen, and a plot of nothing but cells that lack it would be empty."""
    robots = any(
        s.cell.n_robots > 1 and s.added_flag_counts.get(ROBOT_CONTACT_FLAG) is not None for s in summaries
    )
    return tuple(o for o in OUTCOMES if o.name != ROBOT_CONTACT_FLAG or robots)


FIGSIZE: Final[tuple[float, float]] = (6.4, 4.4)  # in
MAX_LEGEND_INSIDE: Final[int] = 8  # legend entries that stand under a plot's axes; more stand beside them
LEGEND_ROW_IN: Final[float] = 0.22  # in, a row of a "small" legend
# in of width per bar: labels slanted at 30 degrees lie half the spacing apart, and a line of text is about
# 0.17 in; FIGSIZE's axes give 14 bars that much, --vary's 24 (12 values x CMPC, DMPC) wrote over each other
BAR_WIDTH_IN: Final[float] = 0.36


PLOT_AXES: Final[tuple[str, ...]] = ("humans", "robots", "method")  # what a report's plots are drawn against


def plot_axis(summaries: Sequence[CellSummary]) -> str:
    """What the plots go against: the number of humans where the cells have several, else the number of
    robots where they have several, else the methods."""
    if len({s.cell.n_humans for s in summaries}) > 1:
        return "humans"
    return "robots" if len({s.cell.n_robots for s in summaries}) > 1 else "method"


def plot_filename(outcome: str, axis: str) -> str:
    """``OUTCOME_by_method.png``, ``OUTCOME_vs_humans.png`` or ``OUTCOME_vs_robots.png`` (``plot_axis``)."""
    return f"{outcome}_by_method.png" if axis == "method" else f"{outcome}_vs_{axis}.png"


def _values(cells: Sequence[CellSummary], name: str) -> tuple[np.ndarray, np.ndarray]:
    """Our values and their error bars, (2, K) below/above (nan where there is none)."""
    if name == "control_step":
        y = np.array([s.step_median_ms for s in cells], dtype=float)
        above = np.array([s.step_p95_ms for s in cells], dtype=float) - y
        return y, np.vstack([np.zeros_like(y), above])
    if name == "travel_time":
        y = np.array([s.travel_time_mean for s in cells], dtype=float)
        half = np.array([s.travel_time_ci for s in cells], dtype=float)
        return y, np.vstack([half, half])
    rates = [_rate(s, name) for s in cells]
    y = np.array([math.nan if r is None else r.percent for r in rates], dtype=float)
    low, high = np.array([(math.nan, math.nan) if r is None else r.interval for r in rates], dtype=float).T
    return y, np.vstack([y - low, high - y])  # Wilson's bounds hold the rate: both lengths are >= 0


def _rate(s: CellSummary, name: str) -> Rate | None:
    """The cell's rate ``name``; for a flag added after the first records (robot-robot contact), None when
    some record of the cell predates it, as the table's "—" (tables._added_rate_cell)."""
    if name not in ADDED_FLAGS:
        rate: Rate = getattr(s, name)
        return rate
    return s.added_rate(name)


def _paper(cells: Sequence[CellSummary], name: str) -> list[float | None]:
    values = [getattr(s.paper, name, None) if s.paper else None for s in cells]
    return [v if v is not None and math.isfinite(v) else None for v in values]


def _draw_by_method(ax: Any, methods: list[str], summaries: Sequence[CellSummary], outcome: Outcome) -> bool:
    """The bars; whether any has an error bar (a travel time of fewer than two successes has none). A method
    without a value has its slot say why (``outcome.missing``) rather than stand empty like a rate of 0."""
    from matplotlib.patches import Patch

    name = outcome.name
    cells = [next(s for s in summaries if s.cell.method == m) for m in methods]
    y, err = _values(cells, name)
    x = np.arange(len(methods))
    colors = [method_style(k)["color"] for k in range(len(methods))]
    drawn = not np.isnan(err).all()
    ax.bar(x, y, yerr=err if drawn else None, color=colors, capsize=4)
    _mark_gaps(ax, x, y, err, cells, outcome)
    paper = [(k, v) for k, v in enumerate(_paper(cells, name)) if v is not None]
    if paper:
        px, py = zip(*paper, strict=True)
        (mark,) = ax.plot(px, py, ls="none", marker="s", ms=8, mfc="none", mec="k", label="paper")
        # The bars' colours are the methods' (named on the x axis): the legend's bar is neutral, not C0.
        what = "ours (a bar per method, 95% interval)" if drawn else "ours (a bar per method)"
        ours = Patch(facecolor="0.8", edgecolor="0.3", label=what)
        # under the axes, as _legend's: inside, matplotlib's least-data corner still covered a bar's foot
        fig = ax.figure
        fig.set_size_inches(fig.get_size_inches()[0], FIGSIZE[1] + LEGEND_ROW_IN)
        fig.legend(handles=[ours, mark], loc="outside lower center", ncols=2, fontsize="small")
    ax.set_xticks(x, methods, rotation=30, ha="right")
    ax.set_xlim(-0.6, len(methods) - 0.4)  # with no bar at all the slots had shrunk onto the frame's edges
    return drawn


def _mark_gaps(
    ax: Any, x: np.ndarray, y: np.ndarray, err: np.ndarray, cells: Sequence[Any], o: Outcome
) -> None:
    """Write into each slot without a bar why (``o.missing``: an empty slot read as 0 s), and above a bar
    whose value has no error bar the one episode it stands on (the title promises intervals)."""
    bottom = ax.get_xaxis_transform()  # x in data, y in axes fraction: at the foot whatever the y limits
    for k in np.flatnonzero(np.isnan(y)):
        ax.text(
            x[k], 0.02, o.missing, transform=bottom, rotation=90, ha="center", va="bottom", fontsize="small"
        )
    _mark_lone(ax, x, y, err, cells, o, "k")


def _mark_lone(
    ax: Any, x: np.ndarray, y: np.ndarray, err: np.ndarray, cells: Sequence[Any], o: Outcome, color: str
) -> None:
    """Above a travel time without an error bar, the one success it stands on: the title promises each
    value its interval, and a bare point read as an exact one."""
    if o.name != "travel_time":
        return
    for k in np.flatnonzero(~np.isnan(y) & np.isnan(err).any(axis=0)):
        text = f"n = {cells[int(k)].success.count}"
        ax.annotate(
            text,
            (x[k], y[k]),
            xytext=(0, 4),
            textcoords="offset points",
            ha="center",
            color=color,
            fontsize="small",
        )


def _dodges(methods: list[str], sizes: list[int]) -> dict[str, float]:
    """Each method's shift along the x axis, in humans: methods with equal values at a crowd size (all at
    100 % success, say) drew their points, error bars and lines on top of each other, so that only the last
    one drawn showed. The methods spread over a fifth of the closest two crowd sizes' gap, centred on it."""
    gap = min(np.diff(sizes), default=1)
    step = 0.2 * gap / max(len(methods) - 1, 1)
    return {m: (k - (len(methods) - 1) / 2) * step for k, m in enumerate(methods)}


def _draw_vs(
    ax: Any,
    lines: dict[str, list[CellSummary]],
    outcome: Outcome,
    size: Callable[[CellSummary], int],
    axis: str,
) -> bool:
    """A line per method (``lines``: its cells) against ``size`` of their cells; whether any point has an
    error bar. A method with no value at all (no success, for the travel time) is named so in the legend,
    as the safety trade-off names it; each point without a value is marked where it would stand."""
    name = outcome.name
    drawn = False
    sizes = sorted({size(s) for cells in lines.values() for s in cells})
    methods = list(lines)
    dodge = _dodges(methods, sizes)
    gaps: dict[int, list[tuple[str, dict[str, str]]]] = {}
    for k, method in enumerate(methods):
        cells = sorted(lines[method], key=size)
        x = np.array([size(s) for s in cells], dtype=float) + dodge[method]
        y, err = _values(cells, name)
        drawn = drawn or not np.isnan(err).all()
        style = method_style(k)
        color = style["color"]
        label = f"{method} (ours)" if not np.isnan(y).all() else f"{method} (ours, {outcome.missing})"
        ax.errorbar(x, y, yerr=err, capsize=3, label=label, **style)
        for s in (s for s, v in zip(cells, y, strict=True) if np.isnan(v)):
            gaps.setdefault(size(s), []).append((method, style))
        _mark_lone(ax, x, y, err, cells, outcome, color)
        paper = [
            (size(s) + dodge[method], v)
            for s, v in zip(cells, _paper(cells, name), strict=True)
            if v is not None
        ]
        if paper:
            px, py = zip(*paper, strict=True)
            ax.plot(px, py, ls="--", marker="s", mfc="none", color=color, label=f"{method} (paper)")
    _mark_missing(ax, gaps, dodge, outcome.missing)
    ax.set_xticks(sizes)
    ax.set_xlabel(f"number of {axis}")
    _legend(ax)
    return drawn


def _mark_missing(
    ax: Any, gaps: dict[int, list[tuple[str, dict[str, str]]]], dodge: dict[str, float], missing: str
) -> None:
    """An open marker at the foot of the axes for each point without a value (a line simply broke there, as
    if the cell had not run), and above them which methods and why (``missing``: "not recorded" for a cell
    whose records predate robot_contact, "no success" for a travel time)."""
    foot = ax.get_xaxis_transform()  # x in data, y in axes fraction
    for at, methods in gaps.items():
        for method, style in methods:
            x = at + dodge[method]
            ax.plot(
                x, 0.03, transform=foot, ls="none", marker=style["marker"], mfc="none", mec=style["color"]
            )
        # one method's name and why; several share the reason, their markers in their colours tell them
        # apart (their names rose past the axes into the title)
        color = methods[0][1]["color"] if len(methods) == 1 else "k"
        box = {"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8}
        text = f"{methods[0][0]}: {missing}" if len(methods) == 1 else missing
        ax.text(
            at,
            0.07,
            text,
            transform=foot,
            rotation=90,
            ha="center",
            va="bottom",
            color=color,
            fontsize="small",
            bbox=box,
        )


def _lines(
    experiment: Experiment, methods: list[str], summaries: Sequence[CellSummary], axis: str
) -> dict[str, list[CellSummary]]:
    """Each line's cells: a method's across crowd sizes; against robots, the columns that differ only in
    their number of robots (``CMPC robots=3``, ``CMPC robots=6`` make the line ``CMPC``)."""
    lines: dict[str, list[CellSummary]] = {}
    for method in methods:
        line = method
        if axis == "robots" and method in experiment.method_robots:
            line = method.removesuffix(f" robots={experiment.method_robots[method]}")
        lines.setdefault(line, []).extend(s for s in summaries if s.cell.method == method)
    return lines


def _legend(ax: Any) -> None:
    """The legend under the axes, two entries a row, on a figure made taller for it, or, past
    ``MAX_LEGEND_INSIDE`` entries, beside them on a figure widened for it: inside, where matplotlib found
    the least data, it still covered the points of rates at 0 % and the foot of their error bars, and the
    safety experiment's 16 methods made a legend over the middle of the plot."""
    handles, labels = ax.get_legend_handles_labels()
    if len(labels) <= MAX_LEGEND_INSIDE:
        rows = math.ceil(len(labels) / 2)
        ax.figure.set_size_inches(FIGSIZE[0], FIGSIZE[1] + LEGEND_ROW_IN * rows)
        ax.figure.legend(handles, labels, loc="outside lower center", ncols=2, fontsize="small")
        return
    ax.figure.set_size_inches(FIGSIZE[0] + 2.8, max(FIGSIZE[1], 1.2 + 0.2 * len(labels)))
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize="small")


def outcome_figure(experiment: Experiment, summaries: Sequence[CellSummary], outcome: Outcome) -> Any:
    """The figure of one outcome: against the number of humans or of robots, else by method (``plot_axis``).

    A ``matplotlib.figure.Figure``, as crowdsim.plotting's: no pyplot, so that a report written from a
    notebook neither switches its backend nor adds to its open figures (savefig renders with Agg)."""
    from matplotlib.figure import Figure

    methods = [m for m in experiment.method_labels if any(s.cell.method == m for s in summaries)]
    axis = plot_axis(summaries)
    fig = Figure(figsize=FIGSIZE, layout="constrained")
    ax = fig.add_subplot()
    if axis == "method":
        fig.set_size_inches(max(FIGSIZE[0], 1.3 + BAR_WIDTH_IN * len(methods)), FIGSIZE[1])
        drawn = _draw_by_method(ax, methods, summaries, outcome)
        ax.set_xlabel(f"method ({counted(summaries[0].cell.n_humans, 'human')})")
    else:
        size = (lambda s: s.cell.n_humans) if axis == "humans" else (lambda s: s.cell.n_robots)
        lines = _lines(experiment, methods, summaries, axis)
        drawn = _draw_vs(ax, lines, outcome, size, axis)
        if axis == "robots":
            ax.set_xlabel(f"number of robots ({summaries[0].cell.n_humans} humans)")
    cut = _from_zero(ax, outcome)
    ax.set_ylabel(outcome.ylabel)
    bars = f"error bars: our 95% {outcome.interval}{cut}" if drawn else f"no error bars: {outcome.no_bars}"
    bars = outcome.bars or bars
    # the settings line wrapped too: the safe configuration's ran past both edges, losing the predictor
    shared = wrap_title(settings_line([s.cell for s in summaries]), 70)
    title = "\n".join(t for t in (wrap_title(experiment.title, 70), shared, outcome.meaning, bars) if t)
    ax.set_title(title, fontsize="medium")
    ax.grid(alpha=0.3)
    return fig


def _from_zero(ax: Any, outcome: Outcome) -> str:
    """Every axis from 0, a little below it so that a point at 0 shows whole (one on the frame was half cut
    off, its line lost in the spine); the title's words for intervals cut there (", cut at 0 s"): a
    Student's t interval of few successes reaches below 0 s (14.4 +- 15.2 s over 2), which no travel time
    is, and the axis showed travel times of -20 s. With nothing drawn (no success anywhere) no scale."""
    data = [line.get_ydata() for line in ax.get_lines() if line.get_transform() == ax.transData]
    data += [[bar.get_y() + bar.get_height()] for bar in ax.patches]  # a bar's value; caps are lines
    values = np.concatenate([np.asarray(d, dtype=float).ravel() for d in data]) if data else np.empty(0)
    values = values[np.isfinite(values)]
    if values.size == 0:
        ax.set_ylim(0.0, 1.0)
        ax.set_yticks([])
        return ""
    top = max(ax.get_ylim()[1], 1e-9)
    ax.set_ylim(-0.015 * top, top)
    return ", cut at 0 s" if outcome.name == "travel_time" and values.min() < 0 else ""


def plot_outcomes(experiment: Experiment, summaries: Sequence[CellSummary], out: Path) -> list[Path]:
    """One plot per outcome (``plotted_outcomes``) in ``out``, named by ``plot_filename``; returns their
    paths."""
    axis = plot_axis(summaries)
    written = []
    for outcome in plotted_outcomes(summaries):
        fig = outcome_figure(experiment, summaries, outcome)
        path = out / plot_filename(outcome.name, axis)
        fig.savefig(path, dpi=120)
        written.append(path)
    return written
