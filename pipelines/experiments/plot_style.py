"""What the report's plots share beside their data: each method's colour, line style and marker, titles
wrapped between items, and the line naming the settings every plotted cell shares (pipelines.experiments
.report_plots, .safety_plots, .compare_plot)."""

from __future__ import annotations

import math
import re
import textwrap
from collections.abc import Mapping, Sequence
from typing import Final

from crowdsim.world import PAPER_ROBOTS
from pipelines.experiments.tasks import Cell
from predictors.text_table import counted

# Colours past matplotlib's ten (C0..C9): tab20b's, then tab20c's, darkest shades first, so that each of up
# to 50 methods has its own (the safety experiment's 16 repeated six of C0..C9, told apart by marker alone).
_MORE_COLORS: Final[tuple[str, ...]] = (
    *("#393b79", "#637939", "#8c6d31", "#843c39", "#7b4173", "#6b6ecf", "#b5cf6b", "#e7ba52"),
    *("#d6616b", "#ce6dbd", "#5254a3", "#8ca252", "#bd9e39", "#ad494a", "#a55194", "#9c9ede"),
    *("#cedb9c", "#e7cb94", "#e7969c", "#de9ed6", "#3182bd", "#e6550d", "#31a354", "#756bb1"),
    *("#636363", "#9ecae1", "#fdae6b", "#a1d99b", "#bcbddc", "#bdbdbd", "#6baed6", "#fd8d3c"),
    *("#74c476", "#9e9ac8", "#969696", "#c6dbef", "#fdd0a2", "#c7e9c0", "#dadaeb", "#d9d9d9"),
)


def method_style(k: int) -> dict[str, str]:
    """The ``k``-th method's colour, line style and marker: matplotlib's ten colours, then ``_MORE_COLORS``
    (no two methods of up to 50 share one), with dashed lines and triangles for the next ten, dotted and
    diamonds after, so that a legend tells them apart in grey too. Squares are the paper's."""
    palette = [f"C{j}" for j in range(10)] + list(_MORE_COLORS)
    return {
        "color": palette[k % len(palette)],
        "ls": ("-", "--", ":")[k // 10 % 3],
        "marker": ("o", "^", "D")[k // 10 % 3],
    }


# A column's marker by its team, where the columns of one method across teams share a colour (method_styles)
_TEAM_MARKERS: Final[tuple[str, ...]] = ("o", "^", "D", "v", "P", "X")


def method_styles(
    methods: Sequence[str], method_robots: Mapping[str, int], by_robots: bool
) -> dict[str, dict[str, str]]:
    """Each column's look (``methods``: the labels plotted, in order), the colour of its line in the outcome
    plots (report_plots._lines): the k-th method's, or ``by_robots`` (those plots against the number of
    robots) that of the method its team's column belongs to, "CMPC robots=3" and "CMPC robots=6" both
    CMPC's, with a marker per team. The safety plots coloured each column apart, so one sweep's figures gave
    "orca robots=3" the orange that its outcome plots gave straight."""
    teams = sorted({method_robots[m] for m in methods if m in method_robots})

    def line(method: str) -> str:
        if by_robots and method in method_robots:
            return method.removesuffix(f" robots={method_robots[method]}")
        return method

    lines = list(dict.fromkeys(line(m) for m in methods))
    styles = {}
    for method in methods:
        style = method_style(lines.index(line(method)))
        if by_robots and method in method_robots:
            style["marker"] = _TEAM_MARKERS[teams.index(method_robots[method]) % len(_TEAM_MARKERS)]
        styles[method] = style
    return styles


# "d_min = 0.8, 1.0" of a --vary title: one item, never broken after its comma (the title read "d_min =
# 0.8,", then "1.0" on a line of its own). Possessive: a value ends where the next "KEY =" starts.
_VALUE_LIST = re.compile(r"[^\s,;]+ = [^\s,;]++(?:, [^\s,;=]++(?! =))*")
_GLUE: Final[str] = "\u00a0"  # no-break space: textwrap breaks at ASCII whitespace only


def wrap_title(title: str, width: int) -> str:
    """``title`` wrapped at ``width`` characters between words, but never inside a value list."""
    glued = _VALUE_LIST.sub(lambda m: m.group(0).replace(" ", _GLUE), title)
    return textwrap.fill(glued, width, break_long_words=False).replace(_GLUE, " ")


def settings_line(cells: Sequence[Cell]) -> str:
    """What every plotted cell shares that changes its figures and neither the methods' labels nor the
    experiment's title say (table.md's notes do): the predictor, the margins, a profile or visibility other
    than the paper's, a team other than the paper's, Table I's values replaced (``--set mpc.KEY``). A Table
    II plot of constant velocity at d_min 1.0 was titled as the paper's Table II, and so was one of two
    robots (``--robots 2``). Empty where there is nothing to say."""
    predicting = [c for c in cells if c.spec.kind.uses_predictor]
    parts = []
    for what, values in (
        ("predictor", {c.spec.predictor_name for c in predicting}),
        ("margins", {c.spec.margins.label for c in predicting}),
    ):
        if len(values) == 1:
            parts.append(f"{what} {values.pop()}")
    for name, paper in (("profile", "paper"), ("visibility", "visible")):
        worlds = {getattr(c.world, name) for c in cells}
        if len(worlds) == 1 and (value := worlds.pop()) != paper:
            parts.append(f"{name} {value}")
    teams = {c.n_robots for c in cells}  # several: the plots go against them, or label their columns
    if len(teams) == 1 and (team := teams.pop()) != PAPER_ROBOTS:
        parts.append(counted(team, "robot"))
    shared = set.intersection(*(set(c.spec.mpc_overrides) for c in predicting)) if predicting else set()
    shown = sorted((key, value) for key, value in shared if key != "jit")  # jit changes no figure
    if shown:
        parts.append("MPC " + ", ".join(f"{key}={value}" for key, value in shown))
    return "; ".join(parts)


# A "small" legend's width past its texts, in its font size (em): each column's handle and the gap to its text
# (2.0 + 0.8), the gap between two columns (2.0), the border and frame (1.0); one column measured 0.43 in
# past its widest 8.33 pt text
LEGEND_HANDLE_EM: Final[float] = 2.8
LEGEND_COLUMN_GAP_EM: Final[float] = 2.0
LEGEND_BORDER_EM: Final[float] = 1.0


def legend_width(labels: Sequence[str], title: str, columns: int) -> float:
    """The width (in) of a "small" legend of ``labels`` in ``columns`` (filled down, as matplotlib fills
    them) under ``title`` (lines apart), measured on the font before any figure is drawn."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextToPath

    prop = FontProperties(size="small")
    measure = TextToPath().get_text_width_height_descent

    def width(text: str) -> float:
        return max(
            (measure(line, prop, ismath=False)[0] / 72 for line in text.split("\n") if line), default=0
        )

    em = prop.get_size_in_points() / 72
    rows = max(1, math.ceil(len(labels) / columns))
    texts = sum(max(map(width, labels[k : k + rows])) for k in range(0, len(labels), rows))
    entries = texts + columns * LEGEND_HANDLE_EM * em + (columns - 1) * LEGEND_COLUMN_GAP_EM * em
    return max(entries, width(title)) + LEGEND_BORDER_EM * em
