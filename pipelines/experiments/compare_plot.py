"""``crowdmpc compare --plot``: each run's change against the first, per method and crowd size, with its 95 %
interval: success, collision and contact in percentage points (Newcombe's paired interval), travel time in
s over the episodes both completed (Student's t), a panel each (pipelines.experiments.compare)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Final

from pipelines.experiments.plot_style import method_style

PANELS: Final[tuple[tuple[str, str], ...]] = (
    ("success", "success (pp)"),
    ("collision", "collision (pp)"),
    ("contact", "contact (pp)"),
    ("travel", "travel time (s), both completed"),
)
SPREAD: Final[float] = 0.5  # of the distance between neighbouring x positions, taken by the lines' offsets


def _change(versus: Mapping[str, Any], panel: str) -> tuple[float | None, float | None, float | None]:
    """(estimate, lower, upper) of one panel's change; None where there is none (no episode both completed,
    or fewer than two for an interval)."""
    if panel == "travel":
        travel = versus["travel_difference"]
        mean, half = travel["mean"], travel["half_width_95"]
        if mean is None:
            return None, None, None
        return mean, None if half is None else mean - half, None if half is None else mean + half
    flag = versus[panel]
    low, high = flag["interval_pp"]
    return flag["difference_pp"], low, high


def compare_figure(report: Mapping[str, Any]) -> Any:
    """A ``matplotlib.figure.Figure`` (not pyplot's: a notebook's figures stay as they were) of ``report``,
    the JSON document of ``crowdmpc compare``: x the crowd sizes run (the groups, each named in full, where
    every group has one), a series per method, team and run after the first; panels two to a row."""
    from matplotlib.figure import Figure

    groups = report["groups"]
    first = report["runs"][0]["label"]
    by_humans = len({g["humans"] for g in groups}) > 1
    teams = len({g["robots"] for g in groups}) > 1
    series: dict[str, list[tuple[Any, Mapping[str, Any]]]] = {}
    for g in groups:
        for label, versus in g["versus_first"].items():
            team = f", {g['robots']} robots" if teams else ""
            name = f"{g['method']}{team}: {label} − {first}"
            series.setdefault(name if by_humans else f"{label} − {first}", []).append((g, versus))
    # One x position per crowd size run (or per method), evenly spaced: a line across 5 and 7 humans read
    # as if 6 had run, and the axis had ticks at 5.5 humans.
    ticks = _ticks(groups, by_humans)
    figure = Figure(figsize=(9.6, 7.0), layout="constrained")
    axes = list(figure.subplots(2, 2, sharex=True).flat)
    for k, (name, points) in enumerate(series.items()):
        offset = SPREAD * ((k + 0.5) / len(series) - 0.5)
        look = method_style(k)  # past ten series, other colours and markers rather than C0 again
        for ax, (panel, _) in zip(axes, PANELS, strict=True):
            xs, ys, below, above = [], [], [], []
            for g, versus in points:
                y, low, high = _change(versus, panel)
                x = list(ticks).index(g["humans"] if by_humans else g["method"]) + offset
                if panel == "travel" and (y is None or low is None):  # a bare point read as exact
                    _mark(ax, x, y, versus, look["color"])
                if y is None:
                    continue
                xs.append(x)
                ys.append(y)
                below.append(0.0 if low is None else y - low)
                above.append(0.0 if high is None else high - y)
            # Points without lines: each crowd size is a comparison of its own, not a curve between them.
            ax.errorbar(
                xs,
                ys,
                yerr=[below, above],
                ls="none",
                capsize=3,
                label=name,
                marker=look["marker"],
                color=look["color"],
            )
    for ax, (_, title) in zip(axes, PANELS, strict=True):
        ax.axhline(0.0, color="0.5", linewidth=0.8)
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        ax.set_xticks(range(len(ticks)), list(ticks.values()))
        ax.tick_params(labelbottom=True)
        ax.set_xlim(-0.5, len(ticks) - 0.5)  # the outermost points off the panel's edges
        ax.set_xlabel("humans" if by_humans else "method")
        ax.set_ylabel(f"change against {first}", fontsize=9)
    handles, labels = axes[0].get_legend_handles_labels()  # every panel has each series: one entry each
    figure.legend(
        handles,
        labels,
        loc="outside lower center",
        ncols=min(3, len(series)),
        fontsize=9,
        title="95 % intervals",
    )
    shared = report["shared_episodes"]
    figure.suptitle(
        f"Paired on {shared} shared episode{'' if shared == 1 else 's'} (crowdmpc compare)", fontsize=11
    )
    return figure


def _mark(ax: Any, x: float, y: float | None, versus: Mapping[str, Any], color: str) -> None:
    """Where a change has no interval, why: no episode both runs completed (a travel time; the method had
    simply vanished from its panel), or one pair only (its point alone, under a legend promising 95 %
    intervals)."""
    if y is None:
        foot = ax.get_xaxis_transform()  # x in data, y in axes fraction
        ax.text(x, 0.03, "none completed by both", transform=foot, rotation=90, ha="center", va="bottom",
                color=color, fontsize="small")  # fmt: skip
        return
    n = versus["travel_difference"]["n"]
    # beside the point, not above it: a point at the top of its panel put the words over the panel's title
    ax.annotate(f"n = {n}", (x, y), xytext=(6, 0), textcoords="offset points", ha="left", va="center",
                color=color, fontsize="small")  # fmt: skip


def _ticks(groups: list[Mapping[str, Any]], by_humans: bool) -> dict[Any, str]:
    """The x positions' keys (crowd sizes, ascending, or methods) and their labels; a method's names its
    crowd size and team as well (one group showed "cmpc" alone)."""
    if by_humans:
        return {n: str(n) for n in sorted({g["humans"] for g in groups})}
    ticks: dict[Any, str] = {}
    for g in groups:
        robots = sorted({h["robots"] for h in groups if h["method"] == g["method"]})
        team = ", ".join(str(r) for r in robots)
        ticks.setdefault(g["method"], f"{g['method']}\n{g['humans']} humans, {team} robots")
    return ticks
