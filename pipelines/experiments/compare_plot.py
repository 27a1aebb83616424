"""``crowdmpc compare --plot``: each run's change against the first, per method and crowd size, with its 95 %
interval: success, collision, contact and discomfort in percentage points (Newcombe's paired interval), travel
time in s over the episodes both completed (Student's t), a panel each (pipelines.experiments.compare)."""

from __future__ import annotations

import json
import textwrap
from collections.abc import Mapping
from typing import Any, Final

from pipelines.experiments.plot_style import method_style
from predictors.text_table import counted

PANELS: Final[tuple[tuple[str, str], ...]] = (
    ("success", "success (pp)"),
    ("collision", "collision (pp)"),
    ("contact", "contact (pp)"),
    ("discomfort", "discomfort (pp)"),
    ("travel", "travel time (s), both completed"),
)
# Panels two to a row, each about 4.2 x 2.4 in (MAX_LEVEL_NOTES, HEAD_ROOM): three rows for the five, the
# sixth place left empty; the title and the legend below take the rest of the height.
ROWS: Final[int] = 3
FIGURE_SIZE: Final[tuple[float, float]] = (9.6, 9.6)
SPREAD: Final[float] = 0.5  # of the distance between neighbouring x positions, taken by the lines' offsets
# Up to this many x positions, a column of the travel panel (about 4 in wide) is wider than "n = 1" (0.35 in
# at 8.3 pt): the note reads across; past it, it stands upright.
MAX_LEVEL_NOTES: Final[int] = 8
# The room added above the travel panel's points for "n = 1", as a fraction of their range (level, upright):
# a line of the small font, or the words upright, in a panel about 2.4 in high.
HEAD_ROOM: Final[tuple[float, float]] = (0.12, 0.3)
# The settings a run after the first ran with otherwise, named under the title (the rest counted), each value
# up to VALUE_CHARS characters, a line wrapped at SETTINGS_WIDTH (the figure's 9.6 in at 11 pt)
MAX_SETTINGS_NAMED: Final[int] = 2
VALUE_CHARS: Final[int] = 24
SETTINGS_WIDTH: Final[int] = 100
_GLUE: Final[str] = "\u00a0"  # no-break space: textwrap breaks at ASCII whitespace only
# A panel without a point (no episode completed by both runs): its axis either side of zero, in its unit.
EMPTY_SPAN: Final[float] = 1.0


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
    series = _series(groups, first, by_humans)
    # One x position per crowd size run (or per method), evenly spaced: a line across 5 and 7 humans read
    # as if 6 had run, and the axis had ticks at 5.5 humans.
    ticks = _ticks(groups, by_humans)
    figure = Figure(figsize=FIGURE_SIZE, layout="constrained")
    axes = list(figure.subplots(ROWS, 2, sharex=True).flat)
    for spare in axes[len(PANELS) :]:  # an empty frame read as a panel without any point
        spare.remove()
    axes = axes[: len(PANELS)]
    notes: dict[int, list[tuple[float, int | None, dict[str, str]]]] = {}  # per x position (_mark_travel)
    pointed: set[str] = set()  # the panels with a point of some series
    for k, (name, points) in enumerate(series.items()):
        offset = SPREAD * ((k + 0.5) / len(series) - 0.5)
        look = method_style(k)  # past ten series, other colours and markers rather than C0 again
        for ax, (panel, _) in zip(axes, PANELS, strict=True):
            xs, ys, below, above = [], [], [], []
            for g, versus in points:
                y, low, high = _change(versus, panel)
                at = list(ticks).index(g["humans"] if by_humans else g["method"])
                x = at + offset
                if panel == "travel" and (y is None or low is None):  # a bare point read as exact
                    pairs = None if y is None else versus["travel_difference"]["n"]
                    notes.setdefault(at, []).append((x, pairs, look))
                if y is None:
                    continue
                pointed.add(panel)
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
    for ax, (panel, title) in zip(axes, PANELS, strict=True):
        ax.axhline(0.0, color="0.5", linewidth=0.8)
        if panel not in pointed:  # the zero line alone gave a range of 1e-17 s, zero off it
            ax.set_ylim(-EMPTY_SPAN, EMPTY_SPAN)
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        ax.set_xticks(range(len(ticks)), list(ticks.values()))
        ax.tick_params(labelbottom=True)
        ax.set_xlim(-0.5, len(ticks) - 0.5)  # the outermost points off the panel's edges
        ax.set_xlabel("humans" if by_humans else "method")
        ax.set_ylabel(f"change against {first}", fontsize=9)
    _mark_travel(axes[-1], notes, len(ticks))
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
    title = f"Paired on {counted(shared, 'shared episode')} (crowdmpc compare)"
    figure.suptitle("\n".join([title, *_settings_lines(report)]), fontsize=11)
    return figure


def _settings_lines(report: Mapping[str, Any]) -> list[str]:
    """Under the title, what each run after the first ran with otherwise (``settings_differ``: its first
    settings named, the rest counted), or that it ran with the first's: the figure named the runs by their
    labels alone, so a PNG of the paper's predictor against constant velocity did not say what changed.
    No line for a report without ``settings_differ``."""
    first = report["runs"][0]["label"]
    lines = []
    for label, rows in report.get("settings_differ", {}).items():
        if not rows:
            lines.append(f"{label} ran with the settings of {first}")
            continue
        items = [
            f"{row['setting']} {_value(row['first'])} → {_value(row['this'])}"
            for row in rows[:MAX_SETTINGS_NAMED]
        ]
        more = rows[MAX_SETTINGS_NAMED:]
        items += [f"{counted(len(more), 'more setting')} (crowdmpc compare lists them)"] if more else []
        # broken between the settings only: "... → \nnull" had parted a value from its setting
        glued = "; ".join(item.replace(" ", _GLUE) for item in items)
        text = textwrap.fill(f"{label} against {first}: {glued}", SETTINGS_WIDTH, break_long_words=False)
        lines.append(text.replace(_GLUE, " "))
    return lines


def _value(text: str) -> str:
    """A setting's values as compare's JSON holds them ('"social_lstm_eth"', 'null | 1.0'), a string
    without its quotes, shortened to ``VALUE_CHARS``."""
    try:
        value = json.loads(text)
    except ValueError:  # several values joined by " | ", or "(not recorded)"
        value = text
    shown = value if isinstance(value, str) else text
    return shown if len(shown) <= VALUE_CHARS else shown[: VALUE_CHARS - 1] + "…"


def _series(
    groups: list[Mapping[str, Any]], first: str, by_humans: bool
) -> dict[str, list[tuple[Any, Mapping[str, Any]]]]:
    """Each series' name and its points (a group and its run's change against ``first``): one per method,
    team and run after the first; where the x axis names the methods (``by_humans`` False), one per team and
    run, since a method's teams had shared one x as one series."""
    teams = len({g["robots"] for g in groups}) > 1
    series: dict[str, list[tuple[Any, Mapping[str, Any]]]] = {}
    for g in groups:
        for label, versus in g["versus_first"].items():
            team = counted(g["robots"], "robot")
            if by_humans:
                name = f"{g['method']}{f', {team}' if teams else ''}: {label} − {first}"
            else:
                name = f"{team}: {label} − {first}" if teams else f"{label} − {first}"
            series.setdefault(name, []).append((g, versus))
    return series


def _mark_travel(
    ax: Any, notes: dict[int, list[tuple[float, int | None, dict[str, str]]]], columns: int
) -> None:
    """Where a travel time has no interval, why, in one note per x position (``notes``: each series' x there,
    its number of pairs, None for none, and its look) whatever the number of series: a note beside each
    point ran into the next series' ("n =n = 1") and past the panel's right edge.

    "n = 1" (one pair: its point alone, under a legend promising 95 % intervals) at the head of the column,
    in room added above the points; "none completed by both" (the series had simply vanished from its
    panel) up from its foot where the point would stand, above an open marker for each such series. In the
    series' colour where it is alone, else in black: the bare points and the markers tell the series apart.
    """
    column = ax.get_xaxis_transform()  # x in data, y in axes fraction
    upright = columns > MAX_LEVEL_NOTES
    if any(pairs is not None for marks in notes.values() for _, pairs, _ in marks):
        low, high = ax.get_ylim()  # after the points and the zero line: fixed from here on
        ax.set_ylim(low, high + (HEAD_ROOM[upright] * (high - low)))
    for at, marks in notes.items():
        lone = [(pairs, look) for _, pairs, look in marks if pairs is not None]
        gone = [(x, look) for x, pairs, look in marks if pairs is None]
        if lone:
            counts = ", ".join(str(n) for n in sorted({pairs for pairs, _ in lone}))
            ax.text(at, 0.97, f"n = {counts}", transform=column, rotation=90 if upright else 0, ha="center",
                    va="top", color=_colour(lone), fontsize="small")  # fmt: skip
        for x, look in gone:
            ax.plot(x, 0.03, transform=column, ls="none", marker=look["marker"], mfc="none",
                    mec=look["color"])  # fmt: skip
        if gone:  # where the first of them would stand: no point of the column there
            ax.text(gone[0][0], 0.07, "none completed by both", transform=column, rotation=90, ha="center",
                    va="bottom", color=_colour(gone), fontsize="small")  # fmt: skip


def _colour(marks: list[tuple[Any, dict[str, str]]]) -> str:
    """A note's colour: its one series', else black."""
    return marks[0][1]["color"] if len(marks) == 1 else "k"


def _ticks(groups: list[Mapping[str, Any]], by_humans: bool) -> dict[Any, str]:
    """The x positions' keys (crowd sizes, ascending, or methods) and their labels; a method's names its
    crowd size and team as well (one group showed "cmpc" alone)."""
    if by_humans:
        return {n: str(n) for n in sorted({g["humans"] for g in groups})}
    ticks: dict[Any, str] = {}
    for g in groups:
        robots = sorted({h["robots"] for h in groups if h["method"] == g["method"]})
        team = counted(robots[0], "robot") if len(robots) == 1 else f"{', '.join(map(str, robots))} robots"
        ticks.setdefault(g["method"], f"{g['method']}\n{counted(g['humans'], 'human')}, {team}")
    return ticks
