"""Plots read in a paper at a 7 in text width: labels apart and inside their panels, legends off the data,
figures at most 12 in wide, every missing value said so, one look per method, compare's axis at the sizes run.
Each test builds the matplotlib Figure and reads its texts, sizes and limits."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from pipelines.experiments.cells import get_experiment
from pipelines.experiments.compare_plot import compare_figure
from pipelines.experiments.plot_style import method_style, wrap_title
from pipelines.experiments.report_plots import OUTCOMES, outcome_figure
from pipelines.experiments.safety_plots import min_distance_hist_figure, safety_tradeoff_figure
from pipelines.experiments.summary import summarize
from tests.pipelines.test_safety_report import _record

MAX_WIDTH_IN = 12.0


def _drawn(fig):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    return fig.canvas.get_renderer()


def _varied_d_min():
    from pipelines.commands.sweep_plan import configured_experiment
    from pipelines.config import load

    return configured_experiment(load(sets=["sweep.experiment=table2", 'sweep.vary="mpc.d_min=0.8,1.0"']))


def _outcome(name):
    return next(o for o in OUTCOMES if o.name == name)


def test_a_title_wraps_between_items_never_inside_a_value_list():
    """The --vary title "...; d_min = 0.8, 1.0" wrapped into "d_min = 0.8," and "1.0" on a line of its own."""
    title = "Table II: centralized (CMPC) vs distributed (DMPC) MPC; d_min = 0.8, 1.0"
    for width in range(20, 80):
        lines = wrap_title(title, width).split("\n")
        assert not any(line.rstrip().endswith("0.8,") for line in lines), width
        assert " ".join(lines) == title
    assert wrap_title("x; simulator a = 1, bb = 2", 14).split("\n") == ["x; simulator", "a = 1, bb = 2"]


def test_few_methods_trade_off_labels_stay_apart_inside_their_panel():
    """`--vary mpc.d_min=0.8,1.0` at 7 humans: four methods, two sharing a point at (0 %, 100 %) and one at
    (0 %, 50 %). Labels at fixed corners wrote "CMPC d_min=0.DMPC d_min=0.8, 18.0 s" and ran over the y
    label; now no two overlap, each stays in the panel, and the legend stands below it. The two methods of
    one point share one label, a line each (placed apart, four methods' labels of one point had hidden one
    whole)."""
    experiment = _varied_d_min()
    cells = experiment.cells((7,))
    # (successes, collisions) of four episodes: two methods at (0 %, 100 %), one at (0, 50), one at (50, 100)
    counts = {0: (4, 0), 1: (4, 0), 2: (2, 0), 3: (4, 2)}
    records = [
        _record(c, i, 1.0, 20, success=i < counts[k][0], collision=i < counts[k][1])
        for k, c in enumerate(cells)
        for i in range(4)
    ]
    fig = safety_tradeoff_figure(experiment, summarize(experiment, cells, records))
    renderer = _drawn(fig)
    (ax,) = fig.axes
    boxes = [t.get_window_extent(renderer) for t in ax.texts]
    lines = [line for t in ax.texts for line in t.get_text().split("\n")]
    assert len(boxes) == 3 and sorted(line.split(",")[0] for line in lines) == sorted(c.method for c in cells)
    frame = ax.get_window_extent(renderer)
    for box in boxes:
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
    for a, b in itertools.combinations(boxes, 2):
        assert not a.overlaps(b)
    legend = ax.get_legend().get_window_extent(renderer)
    assert not legend.overlaps(frame) and legend.y1 < frame.y0
    assert "d_min = 0.8, 1.0" in fig.get_suptitle().replace("\n", " ")
    assert any(line.endswith("d_min = 0.8, 1.0") for line in fig.get_suptitle().split("\n"))


def test_the_trade_off_says_its_intervals_shares_its_axes_and_names_coinciding_points():
    """Five crowd sizes: one panel each, on the same axes (sizes compare by eye), rows of three within
    12 in; the title names the cross-bars; where CMPC and DMPC share a point its legend says so."""
    table2 = get_experiment("table2")
    cells = table2.cells((5, 6, 7, 8, 9))
    # DMPC collides in one episode of four at 9 humans only: everywhere else both methods share (0, 100).
    records = [
        _record(c, i, 1.0, 20, collision=c.method == "DMPC" and c.n_humans == 9 and i == 0)
        for c in cells
        for i in range(4)
    ]
    fig = safety_tradeoff_figure(table2, summarize(table2, cells, records))
    _drawn(fig)
    axes = fig.axes
    visible = [ax for ax in axes if ax.get_visible()]
    assert len(visible) == 5 and fig.get_size_inches()[0] <= MAX_WIDTH_IN
    assert len({round(ax.get_position().y0, 3) for ax in visible}) == 2  # two rows
    assert len({ax.get_xlim() for ax in visible}) == 1 and len({ax.get_ylim() for ax in visible}) == 1
    assert "cross-bars their 95 % Wilson intervals" in fig.get_suptitle().replace("\n", " ")
    notes = [ax.get_legend().get_title().get_text() for ax in visible]
    assert notes[:4] == ["2 methods at (0 %, 100 %)"] * 4 and notes[4] == ""


def test_sixteen_methods_have_sixteen_colours_in_the_legend():
    """The safety experiment: C0..C9 repeated, "motion alpha=0.01" looked like "none" in the legend."""
    from matplotlib.collections import LineCollection
    from matplotlib.colors import to_hex

    assert len({to_hex(method_style(k)["color"]) for k in range(50)}) == 50
    safety = get_experiment("safety")
    cells = safety.cells((7,))
    summaries = summarize(safety, cells, [_record(c, i, 1.0, 20) for c in cells for i in range(2)])
    (ax,) = safety_tradeoff_figure(safety, summaries).axes
    legend = ax.get_legend()
    # a method's legend entry stands for its error bars: a LineCollection in the method's colour
    bars = [h for h in legend.legend_handles if isinstance(h, LineCollection)]
    colours = {to_hex(h.get_color()[0]) for h in bars}
    assert len(colours) == len(cells) == 16
    assert legend.get_title().get_text() == "16 methods at (0 %, 100 %)"


def test_a_histogram_of_five_crowd_sizes_fits_a_page_and_names_its_threshold():
    """min_distance_hist.png of five crowd sizes was 22.8 x 7.2 in with 7 pt legends; its dashed line, the
    metric's collision threshold, was labelled "d_min", which a column may vary for planning."""
    table2 = get_experiment("table2")
    cells = table2.cells((5, 6, 7, 8, 9))
    summaries = summarize(table2, cells, [_record(c, i, 1.0, 20) for c in cells for i in range(2)])
    fig = min_distance_hist_figure(table2, summaries)
    renderer = _drawn(fig)
    assert fig.get_size_inches()[0] <= MAX_WIDTH_IN
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len({round(ax.get_position().x0, 3) for ax in visible}) == 3  # at most three a row
    for ax in visible:
        legend = ax.get_legend()
        labels = [t.get_text() for t in legend.get_texts()]
        assert "collision threshold (0.8 m)" in labels and not any("d_min" in t for t in labels)
        assert min(t.get_fontsize() for t in legend.get_texts()) >= 8.0
        assert not legend.get_window_extent(renderer).overlaps(ax.get_window_extent(renderer))
        steps = [p for p in ax.patches if p.get_label().split(" (")[0] in ("CMPC", "DMPC")]
        assert len({str(p.get_linestyle()) for p in steps}) == 2  # one outline does not hide the other


@pytest.mark.parametrize("figure", [min_distance_hist_figure, safety_tradeoff_figure])
def test_legends_of_many_methods_stay_apart_and_inside_the_figure(figure):
    """`--vary mpc.d_min=0.6,0.65,0.7` at five crowd sizes: six methods a panel. Legends of two columns,
    wider than a panel of a row of three, ran into the next panel's and past the figure's edges."""
    from pipelines.commands.sweep_plan import configured_experiment
    from pipelines.config import load

    sets = ["sweep.experiment=table2", 'sweep.vary="mpc.d_min=0.6,0.65,0.7"']
    experiment = configured_experiment(load(sets=sets))
    cells = experiment.cells((5, 6, 7, 8, 9))
    records = [
        _record(c, i, 0.5 + k / 10, 20, collision=i < k % 3) for k, c in enumerate(cells) for i in range(4)
    ]
    fig = figure(experiment, summarize(experiment, cells, records))
    renderer = _drawn(fig)
    assert fig.get_size_inches()[0] <= MAX_WIDTH_IN
    legends = [ax.get_legend().get_window_extent(renderer) for ax in fig.axes if ax.get_visible()]
    assert len(legends) == 5
    for box in legends:
        assert fig.bbox.x0 <= box.x0 and box.x1 <= fig.bbox.x1 and fig.bbox.y0 <= box.y0, box
    for a, b in itertools.combinations(legends, 2):
        assert not a.overlaps(b)


@pytest.mark.parametrize("sizes", [(5, 6), (5,)])
def test_the_safe_configurations_settings_line_stays_inside_the_figure(sizes):
    """The settings line under the title (predictor, margins, five [mpc] values) ran past both edges of the
    safe configuration's plots, against the humans and by method: "onstant_velocity; ... s"."""
    from pipelines.commands.sweep_plan import configured_experiment
    from pipelines.config import load

    sets = ["sweep.experiment=table2", "controller.predictor=constant_velocity"]
    experiment = configured_experiment(load("docs/examples/safe_crossing.toml", sets=sets))
    cells = experiment.cells(sizes)
    summaries = summarize(experiment, cells, [_record(c, i, 1.0, 20) for c in cells for i in range(2)])
    fig = outcome_figure(experiment, summaries, _outcome("success"))
    renderer = _drawn(fig)
    title = fig.axes[0].title
    assert "predictor constant_velocity" in title.get_text() and "stall_release_s=4" in title.get_text()
    box, page = title.get_window_extent(renderer), fig.bbox
    assert page.x0 <= box.x0 and box.x1 <= page.x1 and box.y1 <= page.y1


def test_a_bar_without_a_travel_time_says_why_and_one_success_says_n_1():
    """`--vary mpc.d_min=0.8,1.0`: CMPC d_min=1.0 never succeeded (an empty slot, read as 0 s) and DMPC
    d_min=1.0 once (no error bar under a title promising them); the legend's one blue bar stood for bars of
    four colours."""
    from matplotlib.colors import to_hex
    from matplotlib.patches import Patch

    experiment = _varied_d_min()
    cells = experiment.cells((7,))
    wins = {0: 2, 1: 0, 2: 2, 3: 1}
    records = [_record(c, i, 1.0, 20, success=i < wins[k]) for k, c in enumerate(cells) for i in range(2)]
    ax = outcome_figure(experiment, summarize(experiment, cells, records), _outcome("travel_time")).axes[0]
    texts = {t.get_text(): t for t in ax.texts}
    assert texts["no success"].get_position()[0] == 1  # CMPC d_min=1.0's slot
    assert texts["n = 1"].xy == (3, pytest.approx(15.0))  # above DMPC d_min=1.0's bar
    (legend,) = ax.figure.legends  # under the axes (inside, it covered a bar's foot)
    assert ax.get_legend() is None
    renderer = _drawn(ax.figure)
    assert not legend.get_window_extent(renderer).overlaps(ax.get_window_extent(renderer))
    (ours,) = [h for h in legend.legend_handles if isinstance(h, Patch)]
    assert to_hex(ours.get_facecolor()) not in {to_hex(f"C{k}") for k in range(10)}
    assert "a bar per method" in ours.get_label()


@pytest.mark.parametrize("outcome", ["travel_time", "robot_contact"])
def test_a_missing_point_across_crowd_sizes_is_marked_where_it_would_stand(outcome):
    """A travel time without success, or a robot_contact rate of records from before the flag, left a gap in
    the line, as if the cell had not run."""
    experiment = get_experiment("controllers").with_predictor("constant_velocity")
    cells = [c for c in experiment.cells((5, 6, 7)) if c.method in ("cmpc", "orca")]
    records = []
    for c in cells:
        gap = c.method == "orca" and c.n_humans == 6
        for i in range(2):
            record = _record(c, i, 1.0, 20, success=not (gap and outcome == "travel_time"))
            if not (gap and outcome == "robot_contact"):
                record["metrics"]["robot_contact"] = False
            records.append(record)
    ax = outcome_figure(experiment, summarize(experiment, cells, records), _outcome(outcome)).axes[0]
    words = "no success" if outcome == "travel_time" else "not recorded"
    (mark,) = [t for t in ax.texts if t.get_text() == f"orca: {words}"]
    assert mark.get_position()[0] == 6
    opened = [
        line for line in ax.get_lines() if line.get_markerfacecolor() == "none" and line.get_label()[0] == "_"
    ]
    assert len(opened) == 1 and math.isclose(opened[0].get_xdata()[0], 6, abs_tol=0.25)


def _versus(difference: float) -> dict:
    flag = {"difference_pp": difference, "interval_pp": [difference - 10.0, difference + 10.0]}
    travel = {"mean": 1.0, "half_width_95": 0.5, "n": 2}
    return {
        "success": flag,
        "collision": flag,
        "contact": flag,
        "discomfort": flag,
        "travel_difference": travel,
    }


def _report(groups: list[tuple[str, int]]) -> dict:
    runs = [{"label": "a"}, {"label": "b"}]
    return {
        "shared_episodes": 4,
        "runs": runs,
        "groups": [
            {"method": m, "humans": h, "robots": 3, "versus_first": {"b": _versus(1.0)}} for m, h in groups
        ],
    }


def test_compare_plots_the_sizes_run_on_whole_ticks_within_a_page():
    """Sizes 5 and 7: ticks at 5.0, 5.5, ..., a line through 6, and a 16.8 x 3.8 in row of four panels."""
    fig = compare_figure(_report([("CMPC", 5), ("CMPC", 7)]))
    _drawn(fig)
    assert fig.get_size_inches()[0] <= MAX_WIDTH_IN
    for ax in fig.axes:
        assert [t.get_text() for t in ax.get_xticklabels()] == ["5", "7"]
        assert all(line.get_linestyle() == "None" for line in ax.get_lines() if line.get_marker() == "o")
    assert len(fig.legends) == 1 and [t.get_text() for t in fig.legends[0].get_texts()] == ["CMPC: b − a"]


def test_compare_draws_a_panel_for_each_of_the_papers_rates_and_travel_time():
    """Discomfort, one of the paper's metrics, had no panel: success, collision, contact and travel time
    only. Five panels now, the rates in percentage points and travel time last, two to a row; no empty frame
    in the sixth place."""
    report = _report([("CMPC", 5)])
    report["groups"][0]["versus_first"]["b"]["discomfort"] = {"difference_pp": -25.0, "interval_pp": [-60, 5]}
    fig = compare_figure(report)
    _drawn(fig)
    titles = [ax.get_title() for ax in fig.axes]
    assert titles == [
        "success (pp)",
        "collision (pp)",
        "contact (pp)",
        "discomfort (pp)",
        "travel time (s), both completed",
    ]
    (point,) = [line for line in fig.axes[3].get_lines() if line.get_marker() == "o"]
    assert list(point.get_ydata()) == [-25.0]
    assert fig.get_size_inches()[0] <= MAX_WIDTH_IN


def test_compare_of_one_group_names_it_in_full_off_the_panel_edges():
    """One group: the axis read "cmpc" alone, its crowd size nowhere, and the points sat on the edges."""
    fig = compare_figure(_report([("cmpc", 5)]))
    for ax in fig.axes:
        (label,) = [t.get_text() for t in ax.get_xticklabels()]
        assert label == "cmpc\n5 humans, 3 robots"
        low, high = ax.get_xlim()
        xs = np.concatenate([line.get_xdata() for line in ax.get_lines() if line.get_marker() == "o"])
        assert low < xs.min() - 0.2 and xs.max() + 0.2 < high


def test_compare_at_one_crowd_size_draws_each_team_apart():
    """A sweep folder resumed with --robots 6 after --robots 3 holds two groups of one method at one crowd
    size: both teams' points stood at the method's one x in one series, one hiding the other and the legend
    naming neither team. A series per team now, each beside the other and named."""
    report = _report([("cmpc", 5), ("cmpc", 5)])
    report["groups"][1] |= {"robots": 6, "versus_first": {"b": _versus(-20.0)}}
    fig = compare_figure(report)
    for ax in fig.axes:
        points = [line for line in ax.get_lines() if line.get_marker() not in (None, "None", "")]
        xs = {float(x) for line in points for x in line.get_xdata()}
        assert len(xs) == 2
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["3 robots: b − a", "6 robots: b − a"]


def test_a_label_beside_a_corner_point_clears_a_shared_points_label():
    """A sweep of two controllers, `--vary scenario.robots=1,3`, at 5 humans: three methods at (83 %, 100 %)
    and one at (100 %, 100 %), the panel's top right corner. The corner's label found no offset clear of the
    three-line label beside it (all within 26 pt of the point) and was laid over it, "orca robots=1, 10.9 s"
    unreadable under "orca robots=3, 12.0 s"."""
    experiment = _varied_d_min()
    cells = experiment.cells((5,))
    counts = {0: (6, 5), 1: (6, 6), 2: (6, 5), 3: (6, 5)}
    records = [
        _record(c, i, 1.0, 27, success=i < counts[k][0], collision=i < counts[k][1])
        for k, c in enumerate(cells)
        for i in range(6)
    ]
    fig = safety_tradeoff_figure(experiment, summarize(experiment, cells, records))
    renderer = _drawn(fig)
    (ax,) = fig.axes
    boxes = [t.get_window_extent(renderer) for t in ax.texts]
    assert len(boxes) == 2
    frame = ax.get_window_extent(renderer)
    for box in boxes:
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
    assert not boxes[0].overlaps(boxes[1])


def test_a_method_keeps_its_colour_from_the_outcome_plots_to_the_safety_plots_across_teams():
    """`sweep --experiment controllers --controllers orca,straight --humans 5 --vary scenario.robots=1,3`:
    success_vs_robots.png drew orca blue and straight orange, a line each across the teams, but the
    histogram and the trade-off coloured each column apart, "orca robots=3" orange. Each column now has its
    method's colour there, its team told apart by line style (histogram) and marker (trade-off)."""
    from matplotlib.colors import to_hex

    from pipelines.commands.sweep_plan import configured_experiment
    from pipelines.config import load

    sets = [
        "sweep.experiment=controllers",
        'sweep.controllers=["orca", "straight"]',
        'sweep.vary="scenario.robots=1,3"',
    ]
    experiment = configured_experiment(load(sets=sets))
    cells = experiment.cells((5,))
    records = [
        _record(c, i, 0.5 + 0.1 * k, 27, success=True, collision=k == 1)
        for k, c in enumerate(cells)
        for i in range(4)
    ]
    summaries = summarize(experiment, cells, records)
    outcome = outcome_figure(experiment, summaries, _outcome("success")).axes[0]
    handles, labels = outcome.get_legend_handles_labels()
    line_colour = {
        label.removesuffix(" (ours)"): to_hex(h.lines[0].get_color())
        for h, label in zip(handles, labels, strict=True)
    }
    assert sorted(line_colour) == ["orca", "straight"] and len(set(line_colour.values())) == 2
    hist = min_distance_hist_figure(experiment, summaries).axes[0]
    stairs = {p.get_label().rsplit(" (", 1)[0]: p for p in hist.patches}
    trade = safety_tradeoff_figure(experiment, summaries)
    assert trade is not None
    for method in (c.method for c in cells):
        base = method.split(" robots=")[0]
        assert to_hex(stairs[method].get_edgecolor()) == line_colour[base], method
    assert len({(p.get_edgecolor(), str(p.get_linestyle())) for p in stairs.values()}) == 4
    markers = {
        line.get_marker() for line in trade.axes[0].get_lines() if line.get_marker() not in ("None", "", None)
    }
    assert len(markers - {"_", "|"}) == 2  # a marker per team (the caps are "_" and "|")
