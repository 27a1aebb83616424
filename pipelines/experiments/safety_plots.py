"""The safety report's plots (pipelines.experiments.safety_report): the histogram of each episode's minimum
robot-human distance, and the success / collision trade-off, one panel per number of humans.

The safety experiment compares 16 methods at one crowd size; its legends stand beside the panels (inside,
they overflowed the panel and covered the title), and where more than ``MAX_ANNOTATED`` methods share a
panel the trade-off names them in such a legend rather than beside each point (16 labels piled up on the
few points where methods agree).
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from crowdsim.metrics import COLLISION_DISTANCE
from pipelines.experiments.report_plots import method_style
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

if TYPE_CHECKING:
    from pipelines.experiments.cells import Experiment

# Methods a trade-off panel labels beside their points: one per corner of a point (_LABEL_CORNERS).
MAX_ANNOTATED: Final[int] = 4
LEGEND_WIDTH: Final[float] = 2.6  # in, added to a panel whose legend stands beside it
_LABEL_CORNERS: Final[tuple[tuple[int, int], ...]] = ((5, 5), (5, -5), (-5, 5), (-5, -5))  # points


def _panels(count: int, size: tuple[float, float], title: str, **kwargs):
    """A figure with ``count`` panels in rows of at most three, the unused ones hidden, and ``title`` wrapped
    to the figure's width (experiment titles are longer than one panel is wide).

    A ``matplotlib.figure.Figure``, not pyplot's: a report written from a notebook neither switches its
    backend (this module called ``matplotlib.use("Agg")``) nor adds to its open figures."""
    from matplotlib.figure import Figure

    ncols = min(3, count)
    nrows = math.ceil(count / ncols)
    fig = Figure(figsize=(size[0] * ncols, size[1] * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **kwargs)
    for ax in axes.flat[count:]:
        ax.set_visible(False)
    fig.suptitle(textwrap.fill(title, width=int(12 * size[0] * ncols)), fontsize="medium")
    return fig, list(axes.flat[:count])


def _beside(ax: Any, **kwargs: Any) -> None:
    """The panel's legend at its right, outside it: nothing drawn or written is covered."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize="x-small", **kwargs)


def _height(size: float, entries: int) -> float:
    """A panel's height (in): ``size``, or more when its legend of ``entries`` lines needs it."""
    return max(size, 0.8 + 0.16 * entries)


def _by_humans(experiment: Experiment, summaries: Sequence[SafetyColumn]) -> dict[int, list[SafetyColumn]]:
    """Summaries per number of humans, each list in the experiment's method order."""
    order = {label: k for k, label in enumerate(experiment.method_labels)}
    groups: dict[int, list[SafetyColumn]] = {}
    for s in sorted(summaries, key=lambda s: (s.cell.n_humans, order.get(s.cell.method, len(order)))):
        groups.setdefault(s.cell.n_humans, []).append(s)
    return groups


def _method_styles(experiment: Experiment) -> dict[str, dict[str, str]]:
    """One style per method, the same in every panel and plot (report_plots.method_style)."""
    return {label: method_style(k) for k, label in enumerate(experiment.method_labels)}


def min_distance_hist_figure(experiment: Experiment, summaries: Sequence[SafetyColumn]) -> Any:
    """Step histograms of each episode's minimum robot-human distance, one per method, overlaid on shared
    bins; one panel per number of humans, since a larger crowd shifts the whole distribution."""
    from matplotlib.ticker import MaxNLocator

    groups = _by_humans(experiment, summaries)
    styles = _method_styles(experiment)
    entries = max(len(cells) for cells in groups.values()) + 3  # + the two thresholds and the title
    size = (5.0 + LEGEND_WIDTH, _height(3.6, entries))
    fig, axes = _panels(len(groups), size, experiment.title, sharex=True, sharey=True)
    for ax, (n, cells) in zip(axes, groups.items(), strict=True):
        for s in cells:
            counts = min_distance_counts(s.min_distances)
            beyond = f", {counts[-1]} beyond {HIST_MAX:g} m" if counts[-1] else ""
            label = f"{s.cell.method} ({s.episodes}{beyond})"
            style = styles.get(s.cell.method, {})
            ax.stairs(
                counts[:-1], HIST_EDGES, color=style.get("color"), ls=style.get("ls"), lw=1.3, label=label
            )
        ax.axvline(CONTACT_DISTANCE, color="k", ls=":", lw=1, label=f"contact ({CONTACT_DISTANCE:g} m)")
        ax.axvline(COLLISION_DISTANCE, color="k", ls="--", lw=1, label=f"d_min ({COLLISION_DISTANCE:g} m)")
        ax.set_xlim(0.0, HIST_MAX)
        ax.set_title(f"{n} humans", fontsize="medium")
        ax.grid(alpha=0.3)
        _beside(ax, title="method (episodes)", title_fontsize="x-small")
    fig.supxlabel("episode's minimum robot-human distance (m)")
    fig.supylabel("episodes")
    # Counts: whole ticks (two episodes a cell were read against ticks of 0.25 episodes). Shared y axes: one
    # locator serves every panel.
    axes[0].yaxis.set_major_locator(MaxNLocator(integer=True))
    return fig


def plot_min_distance_hist(experiment: Experiment, summaries: Sequence[SafetyColumn], path: Path) -> Path:
    fig = min_distance_hist_figure(experiment, summaries)
    fig.savefig(path, dpi=120)
    return path


def _annotation(s: SafetyColumn) -> str:
    time = s.travel_time_mean
    return f"{s.cell.method}, {time:.1f} s" if time == time else f"{s.cell.method}, no success"


def _draw_point(ax: Any, s: SafetyColumn, style: dict[str, str], corner: int | None) -> None:
    """One method's point with its 95% Wilson intervals; its name and travel time at ``corner`` of it
    (_LABEL_CORNERS), or in the legend when None."""
    x, y = s.collision.percent, s.success.percent
    (x_lo, x_hi), (y_lo, y_hi) = s.collision.interval, s.success.interval
    color = style.get("color")
    ax.errorbar(
        x,
        y,
        # Clipped at 0: at a rate of exactly 0 or 100 % the Wilson bound can round past it.
        xerr=[[max(0.0, x - x_lo)], [max(0.0, x_hi - x)]],
        yerr=[[max(0.0, y - y_lo)], [max(0.0, y_hi - y)]],
        fmt=style.get("marker", "o"),
        color=color,
        capsize=3,
        label=_annotation(s) if corner is None else None,
    )
    if corner is None:
        return
    # Neighbouring methods (e.g. close alphas) often sit close together: their labels take turns at the
    # four corners of the point, on a translucent box so that crossings stay legible.
    dx, dy = _LABEL_CORNERS[corner]
    ax.annotate(
        _annotation(s),
        (x, y),
        xytext=(dx, dy),
        textcoords="offset points",
        ha="left" if dx > 0 else "right",
        va="bottom" if dy > 0 else "top",
        fontsize="x-small",
        color=color,
        bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.7},
        zorder=10,  # above every method's error bars, drawn later
    )


def safety_tradeoff_figure(experiment: Experiment, summaries: Sequence[SafetyColumn]) -> Any | None:
    """Success against collision rate per method, both with their 95% Wilson intervals, one panel per
    number of humans that has at least two methods to trade off; None when none has."""
    groups = {n: cells for n, cells in _by_humans(experiment, summaries).items() if len(cells) >= 2}
    if not groups:
        return None
    styles = _method_styles(experiment)
    most = max(len(cells) for cells in groups.values())
    annotated = most <= MAX_ANNOTATED
    size = (5.6, 4.2) if annotated else (5.6 + LEGEND_WIDTH, _height(4.2, most + 1))
    fig, axes = _panels(len(groups), size, experiment.title)
    for ax, (n, cells) in zip(axes, groups.items(), strict=True):
        for k, s in enumerate(cells):
            corner = k % len(_LABEL_CORNERS) if annotated else None
            _draw_point(ax, s, styles.get(s.cell.method, {}), corner)
        ax.axvline(
            COLLISION_TARGET,
            color="grey",
            ls="--",
            lw=1,
            label=f"{COLLISION_TARGET:g} % collisions: the paper's Table II stays below",
        )
        ax.set_xlim(left=min(-0.5, ax.get_xlim()[0]))
        ax.set_xlabel(f"collision rate (%), < {COLLISION_DISTANCE:g} m")
        ax.set_ylabel("success rate (%)")
        where = "beside each method" if annotated else "in the legend"
        ax.set_title(f"{n} humans: mean travel time of successful episodes {where}", fontsize="small")
        ax.grid(alpha=0.3)
        if annotated:
            ax.legend(fontsize="x-small", loc="lower right")
        else:
            _beside(ax, title="method, mean travel time", title_fontsize="x-small")
    return fig


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
