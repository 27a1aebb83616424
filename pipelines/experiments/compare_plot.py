"""``crowdmpc compare --plot``: each run's change against the first, per method and crowd size, with its 95 %
interval: success, collision and contact in percentage points (Newcombe's paired interval), travel time in
s over the episodes both completed (Student's t), a panel each (pipelines.experiments.compare)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Final

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
    the JSON document of ``crowdmpc compare``: x the crowd size (the methods where every group has one), a
    line per method, team and run after the first."""
    from matplotlib.figure import Figure

    groups = report["groups"]
    first = report["runs"][0]["label"]
    by_humans = len({g["humans"] for g in groups}) > 1
    teams = len({g["robots"] for g in groups}) > 1
    lines: dict[str, list[tuple[Any, Mapping[str, Any]]]] = {}
    for g in groups:
        for label, versus in g["versus_first"].items():
            team = f", {g['robots']} robots" if teams else ""
            name = f"{g['method']}{team}: {label} − {first}"
            lines.setdefault(name if by_humans else f"{label} − {first}", []).append((g, versus))
    methods = list(dict.fromkeys(g["method"] for g in groups))
    figure = Figure(figsize=(4.2 * len(PANELS), 3.8), layout="constrained")
    axes = figure.subplots(1, len(PANELS), squeeze=False)[0]
    for k, (name, points) in enumerate(lines.items()):
        offset = SPREAD * ((k + 0.5) / len(lines) - 0.5)
        for ax, (panel, _) in zip(axes, PANELS, strict=True):
            xs, ys, below, above = [], [], [], []
            for g, versus in points:
                y, low, high = _change(versus, panel)
                if y is None:
                    continue
                xs.append((g["humans"] if by_humans else methods.index(g["method"])) + offset)
                ys.append(y)
                below.append(0.0 if low is None else y - low)
                above.append(0.0 if high is None else high - y)
            ax.errorbar(xs, ys, yerr=[below, above], marker="o", capsize=3, label=name)
    for ax, (_, title) in zip(axes, PANELS, strict=True):
        ax.axhline(0.0, color="0.5", linewidth=0.8)
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        if by_humans:
            ax.set_xlabel("humans")
        else:
            ax.set_xticks(range(len(methods)), methods, rotation=30, ha="right")
    axes[0].set_ylabel(f"change against {first}, 95 % interval")
    axes[-1].legend(fontsize=8, loc="best")
    figure.suptitle(f"Paired on {report['shared_episodes']} shared episodes (crowdmpc compare)", fontsize=11)
    return figure
