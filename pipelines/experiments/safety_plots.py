"""The safety report's plots (pipelines.experiments.safety_report): the histogram of each episode's minimum
robot-human distance, and the success / collision trade-off, one panel per number of humans, in rows of at
most three (five crowd sizes made a histogram 22.8 in wide) on shared axes.

Each panel's legend stands under it, off the data (inside, it covered points and error bars; beside, it
widened the figure). Where more than ``MAX_ANNOTATED`` methods share a trade-off panel the legend names
them (16 labels piled up on the few points where methods agree); fewer are labelled beside their points,
each placed where it overlaps no other label and stays inside the panel, and the legend's title counts the
methods that share a point (only the last one drawn shows there).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from crowdsim.metrics import COLLISION_DISTANCE
from pipelines.experiments.plot_style import legend_width, method_styles, settings_line, wrap_title
from pipelines.experiments.safety_report import (
    COLLISION_TARGET,
    CONTACT_DISTANCE,
    HIST_EDGES,
    HIST_MAX,
    MIN_DISTANCE_HIST_PNG,
    SAFETY_TRADEOFF_PNG,
    SafetyColumn,
    min_distance_counts,
)
from predictors.text_table import counted

if TYPE_CHECKING:
    from pipelines.experiments.cells import Experiment

# Methods a trade-off panel labels beside their points; more are named in its legend.
MAX_ANNOTATED: Final[int] = 4
# A panel's width (in) in a row of 1, 2, 3: a figure stays within 11.5 in, so that scaled to a 7 in text width
# its small text (8 pt) still reads at 5 pt; five crowd sizes made a histogram 22.8 in wide.
PANEL_WIDTHS: Final[tuple[float, float, float]] = (6.4, 5.2, 3.8)
PANEL_HEIGHT: Final[float] = 2.9  # in, of a panel's axes and their tick labels
LEGEND_GAP: Final[float] = (
    0.5  # in below a panel's axes, past its tick labels and x label, where its legend starts
)
LEGEND_LINE: Final[float] = 0.2  # in, a line of a "small" legend
LEGEND_MARGIN: Final[float] = 0.2  # in between the legends of two panels side by side
# Where a label may stand from its point (points): the four corners, then above, below, further out. The
# two farthest rings come after every nearer place, so a label clear within 30 pt stands where it stood; they
# are for a point in a panel's corner whose neighbour's label of three lines (three methods at one point)
# filled every nearer place the panel leaves (a corner label had been laid over it).
_OFFSETS: Final[tuple[tuple[int, int], ...]] = (
    tuple((sx * r, sy * r) for r in (5, 14, 26) for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)))
    + ((0, 12), (0, -12), (0, 30), (0, -30))
    + tuple((sx * r, sy * r) for r in (46, 66) for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)))
    + ((0, 50), (0, -50), (0, 70), (0, -70))
)


def _panels(count: int, ncols: int, height: float, title: str, **kwargs: Any) -> tuple[Any, list[Any]]:
    """A figure of ``count`` panels in rows of ``ncols`` (at most three), each ``height`` in tall (axes and
    legend), the unused ones hidden, and each line of ``title`` wrapped to the figure's width between items
    (plot_style.wrap_title).

    A ``matplotlib.figure.Figure``, not pyplot's: a report written from a notebook neither switches its
    backend (this module called ``matplotlib.use("Agg")``) nor adds to its open figures."""
    from matplotlib.figure import Figure

    nrows = math.ceil(count / ncols)
    width = PANEL_WIDTHS[ncols - 1] * ncols
    fig = Figure(figsize=(width, height * nrows + 0.5), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **kwargs)
    for ax in axes.flat[count:]:
        ax.set_visible(False)
    for ax in axes.flat[:count]:
        # Shared axes keep their tick labels: each panel has its legend under it, and a panel above a hidden
        # one had none at all.
        ax.tick_params(labelbottom=True, labelleft=True)
    lines = (wrap_title(line, int(13 * width)) for line in title.split("\n"))
    fig.suptitle("\n".join(lines), fontsize="medium")
    return fig, list(axes.flat[:count])


def _below(ax: Any, columns: int, **kwargs: Any) -> None:
    """The panel's legend under it in ``columns``, clear of its tick labels and x label: nothing drawn is
    covered."""
    from matplotlib.transforms import ScaledTranslation

    ax.legend(
        loc="upper center",
        bbox_to_anchor=(0.5, 0.0),
        bbox_transform=ax.transAxes + ScaledTranslation(0.0, -LEGEND_GAP, ax.figure.dpi_scale_trans),
        borderaxespad=0.0,
        fontsize="small",
        title_fontsize="small",
        ncols=columns,
        **kwargs,
    )


def _layout(legends: Sequence[tuple[Sequence[str], str]]) -> tuple[int, list[int], float]:
    """For panels with legends of (labels, title): the panels a row (at most three, fewer where a legend is
    wider than its panel), each legend's columns (two for more than six entries where two fit under its
    panel) and a panel's height (in: its axes, then the tallest legend). Two columns of --vary's labels ran
    into the next panel's legend and past the figure's edges (three d_min values at five crowd sizes)."""

    def fits(labels: Sequence[str], title: str, columns: int, ncols: int) -> bool:
        return legend_width(labels, title, columns) <= PANEL_WIDTHS[ncols - 1] - LEGEND_MARGIN

    most = min(3, len(legends))
    ncols = next((n for n in range(most, 1, -1) if all(fits(*legend, 1, n) for legend in legends)), 1)
    columns = [2 if len(labels) > 6 and fits(labels, title, 2, ncols) else 1 for labels, title in legends]
    rows = max(
        math.ceil(len(labels) / k) + len(title.splitlines())
        for (labels, title), k in zip(legends, columns, strict=True)
    )
    return ncols, columns, PANEL_HEIGHT + LEGEND_GAP + 0.15 + LEGEND_LINE * rows


def _by_humans(experiment: Experiment, summaries: Sequence[SafetyColumn]) -> dict[int, list[SafetyColumn]]:
    """Summaries per number of humans, each list in the experiment's method order."""
    order = {label: k for k, label in enumerate(experiment.method_labels)}
    groups: dict[int, list[SafetyColumn]] = {}
    for s in sorted(summaries, key=lambda s: (s.cell.n_humans, order.get(s.cell.method, len(order)))):
        groups.setdefault(s.cell.n_humans, []).append(s)
    return groups


def _method_styles(experiment: Experiment, summaries: Sequence[SafetyColumn]) -> dict[str, dict[str, str]]:
    """One style per method, the same in every panel and plot and as the outcome plots colour it: by the
    method a team's column belongs to where they go against the number of robots (plot_style.method_styles;
    report_plots.plot_axis: one crowd size, several teams)."""
    methods = [m for m in experiment.method_labels if any(s.cell.method == m for s in summaries)]
    by_robots = (
        len({s.cell.n_humans for s in summaries}) == 1 and len({s.cell.n_robots for s in summaries}) > 1
    )
    return method_styles(methods, experiment.method_robots, by_robots)


# The histogram's outlines, by method: one on another hid it wholly where their counts agree.
_HIST_STYLES: Final[tuple[Any, ...]] = ("-", "--", "-.", (0, (1, 1)))


def min_distance_hist_figure(experiment: Experiment, summaries: Sequence[SafetyColumn]) -> Any:
    """Step histograms of each episode's minimum robot-human distance, one per method, overlaid on shared
    bins; one panel per number of humans, since a larger crowd shifts the whole distribution."""
    from matplotlib.ticker import MaxNLocator

    groups = _by_humans(experiment, summaries)
    styles = _method_styles(experiment, summaries)
    order = {label: k for k, label in enumerate(experiment.method_labels)}
    contact = f"contact ({CONTACT_DISTANCE:g} m)"
    # The metric's threshold (crowdsim.metrics, Table I), not the planning d_min a column may vary.
    threshold = f"collision threshold ({COLLISION_DISTANCE:g} m)"
    legend_title = "method (episodes)"
    labels = {n: [_hist_label(s) for s in cells] + [contact, threshold] for n, cells in groups.items()}
    ncols, columns, height = _layout([(texts, legend_title) for texts in labels.values()])
    title = _title(experiment, summaries)
    fig, axes = _panels(len(groups), ncols, height, title, sharex=True, sharey=True)
    for ax, (n, cells), k_columns in zip(axes, groups.items(), columns, strict=True):
        for s, label in zip(cells, labels[n], strict=False):
            counts = min_distance_counts(s.min_distances)
            k = order.get(s.cell.method, 0)
            color = styles.get(s.cell.method, {}).get("color")
            ls = _HIST_STYLES[k % len(_HIST_STYLES)]
            ax.stairs(counts[:-1], HIST_EDGES, color=color, ls=ls, lw=1.6, alpha=0.85, label=label)
        ax.axvline(CONTACT_DISTANCE, color="k", ls=":", lw=1, label=contact)
        ax.axvline(COLLISION_DISTANCE, color="k", ls="--", lw=1, label=threshold)
        ax.set_xlim(0.0, HIST_MAX)
        ax.set_title(counted(n, "human"), fontsize="medium")
        ax.set_xlabel("episode's minimum robot-human distance (m)", fontsize="small")
        ax.set_ylabel("episodes", fontsize="small")
        ax.grid(alpha=0.3)
        _below(ax, k_columns, title=legend_title)
    # Counts: whole ticks (two episodes a cell were read against ticks of 0.25 episodes). Shared y axes: one
    # locator serves every panel.
    axes[0].yaxis.set_major_locator(MaxNLocator(integer=True))
    return fig


def _hist_label(s: SafetyColumn) -> str:
    beyond = min_distance_counts(s.min_distances)[-1]
    return f"{s.cell.method} ({s.episodes}{f', {beyond} beyond {HIST_MAX:g} m' if beyond else ''})"


def plot_min_distance_hist(experiment: Experiment, summaries: Sequence[SafetyColumn], path: Path) -> Path:
    fig = min_distance_hist_figure(experiment, summaries)
    fig.savefig(path, dpi=120)
    return path


def _annotation(s: SafetyColumn) -> str:
    time = s.travel_time_mean
    return f"{s.cell.method}, {time:.1f} s" if time == time else f"{s.cell.method}, no success"


def _point(s: SafetyColumn) -> tuple[float, float]:
    return s.collision.percent, s.success.percent


def _draw_point(ax: Any, s: SafetyColumn, style: dict[str, str], named: bool) -> None:
    """One method's point with its 95% Wilson intervals; its name and travel time in the legend when
    ``named``, else beside it (``_place_labels``)."""
    x, y = _point(s)
    (x_lo, x_hi), (y_lo, y_hi) = s.collision.interval, s.success.interval
    ax.errorbar(
        x,
        y,
        # Wilson's bounds hold the rate between them, and are exactly 0 and 100 % at 0 and n of n
        # (summary.wilson_interval): no bar reaches past the point.
        xerr=[[x - x_lo], [x_hi - x]],
        yerr=[[y - y_lo], [y_hi - y]],
        fmt=style.get("marker", "o"),
        color=style.get("color"),
        capsize=3,
        label=_annotation(s) if named else None,
    )


def _coinciding(cells: Sequence[SafetyColumn]) -> str:
    """Lines saying where several methods share one point (only the last one drawn shows there)."""
    at: dict[tuple[float, float], int] = {}
    for s in cells:
        x, y = _point(s)
        at[round(x, 6), round(y, 6)] = at.get((round(x, 6), round(y, 6)), 0) + 1
    return "\n".join(f"{k} methods at ({x:.3g} %, {y:.3g} %)" for (x, y), k in at.items() if k > 1)


def _place_labels(fig: Any, labels: Sequence[tuple[Any, SafetyColumn, str, str]]) -> None:
    """Each (panel, method, colour, text) label beside its point at the first of ``_OFFSETS`` where it stays
    inside the panel and clear of the points and the labels placed before it; failing that, where it
    overlaps least. Measured on the laid-out figure: labels at fixed corners ran into one another ("CMPC
    d_min=0.DMPC d_min=0.8, 18.0 s") and over the y label."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    renderer = fig.canvas.get_renderer()
    taken: dict[Any, list[Any]] = {}
    for ax, s, color, label in labels:
        frame = ax.get_window_extent(renderer).padded(-2)
        dots = [_dot(ax, other) for other_ax, other, _, _ in labels if other_ax is ax]
        best: tuple[float, Any] | None = None
        for dx, dy in _OFFSETS:
            text = ax.annotate(
                label,
                _point(s),
                xytext=(dx, dy),
                textcoords="offset points",
                ha="left" if dx > 0 else "right" if dx < 0 else "center",
                va="bottom" if dy > 0 else "top",
                fontsize="small",
                color=color,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.7},
                zorder=10,  # above every method's error bars, drawn later
                in_layout=False,  # placed inside the panel: the layout measured stays the one drawn
            )
            box = text.get_window_extent(renderer)
            outside = not (
                frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
            )
            clash = sum(_overlap(box, other) for other in taken.get(ax, []) + dots) + 1e9 * outside
            if best is None or clash < best[0]:
                if best is not None:
                    best[1].remove()
                best = (clash, text)
            else:
                text.remove()
            if clash == 0:
                break
        assert best is not None
        taken.setdefault(ax, []).append(best[1].get_window_extent(renderer))


def _dot(ax: Any, s: SafetyColumn) -> Any:
    """A point's marker, in display coordinates."""
    from matplotlib.transforms import Bbox

    x, y = ax.transData.transform(_point(s))
    return Bbox.from_extents(x - 4, y - 4, x + 4, y + 4)


def _overlap(a: Any, b: Any) -> float:
    return max(0.0, min(a.x1, b.x1) - max(a.x0, b.x0)) * max(0.0, min(a.y1, b.y1) - max(a.y0, b.y0))


def safety_tradeoff_figure(experiment: Experiment, summaries: Sequence[SafetyColumn]) -> Any | None:
    """Success against collision rate per method, both with their 95% Wilson intervals, one panel per
    number of humans that has at least two methods to trade off, on shared axes; None when none has."""
    groups = {n: cells for n, cells in _by_humans(experiment, summaries).items() if len(cells) >= 2}
    if not groups:
        return None
    styles = _method_styles(experiment, summaries)
    named = max(len(cells) for cells in groups.values()) > MAX_ANNOTATED
    target = f"{COLLISION_TARGET:g} % collisions: the paper's Table II stays below"
    legends = [
        # a legend lists lines (the target) before the methods' error bars
        ([target, *([_annotation(s) for s in cells] if named else [])], _coinciding(cells))
        for cells in groups.values()
    ]
    ncols, columns, height = _layout(legends)
    where = "in the legend" if named else "beside each method"
    title = (
        f"{_title(experiment, summaries)}\nsuccess against collision rate, the cross-bars their 95 % Wilson "
        f"intervals; mean travel time of the successful episodes {where}"
    )
    fig, axes = _panels(len(groups), ncols, height, title, sharex=True, sharey=True)
    for ax, (n, cells), k_columns in zip(axes, groups.items(), columns, strict=True):
        for s in cells:
            _draw_point(ax, s, styles.get(s.cell.method, {}), named)
        ax.axvline(COLLISION_TARGET, color="grey", ls="--", lw=1, label=target)
        ax.set_xlabel(f"collision rate (%), < {COLLISION_DISTANCE:g} m", fontsize="small")
        ax.set_ylabel("success rate (%)", fontsize="small")
        ax.set_title(counted(n, "human"), fontsize="medium")
        ax.grid(alpha=0.3)
        _below(ax, k_columns, title=_coinciding(cells) or None)
    # Shared by every panel: a point at 0 % collisions stood on the left edge, half cut off; success on its
    # whole scale, 0 to 100 %, where the axis had started at 27 % unmarked
    axes[0].set_xlim(left=min(-1.0, axes[0].get_xlim()[0]))
    axes[0].set_ylim(-3.0, 103.0)
    if not named:
        labels = [
            label
            for ax, (_, cells) in zip(axes, groups.items(), strict=True)
            for label in _labels(ax, cells, styles)
        ]
        _place_labels(fig, labels)
    return fig


def _title(experiment: Experiment, summaries: Sequence[SafetyColumn]) -> str:
    """The experiment's title and, on a line of its own, the settings its cells share (plot_style)."""
    shared = settings_line([s.cell for s in summaries])
    return f"{experiment.title}\n{shared}" if shared else experiment.title


def _labels(
    ax: Any, cells: Sequence[SafetyColumn], styles: dict[str, dict[str, str]]
) -> list[tuple[Any, SafetyColumn, str, str]]:
    """A panel's (panel, method, colour, text) labels: one for the methods that share a point, a line each
    in black, since labels of one point placed apart still covered each other (four methods at (0 %, 100 %),
    one of them hidden whole)."""
    at: dict[tuple[float, float], list[SafetyColumn]] = {}
    for s in cells:
        x, y = _point(s)
        at.setdefault((round(x, 6), round(y, 6)), []).append(s)
    return [
        (ax, group[0], styles.get(group[0].cell.method, {}).get("color", "k"), _annotation(group[0]))
        if len(group) == 1
        else (ax, group[0], "k", "\n".join(_annotation(s) for s in group))
        for group in at.values()
    ]


def plot_safety_tradeoff(
    experiment: Experiment, summaries: Sequence[SafetyColumn], path: Path
) -> Path | None:
    """``safety_tradeoff_figure`` written to ``path``; None (nothing written) when there is none."""
    fig = safety_tradeoff_figure(experiment, summaries)
    if fig is None:
        return None
    fig.savefig(path, dpi=120)
    return path


def plot_safety(experiment: Experiment, summaries: Sequence[SafetyColumn], out: Path) -> list[Path]:
    """The safety plots in ``out`` (the trade-off only where two methods share a crowd size)."""
    written = [plot_min_distance_hist(experiment, summaries, out / MIN_DISTANCE_HIST_PNG)]
    tradeoff = plot_safety_tradeoff(experiment, summaries, out / SAFETY_TRADEOFF_PNG)
    return written + ([tradeoff] if tradeoff else [])
