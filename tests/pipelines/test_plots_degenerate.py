"""The report's plots where a run gives them little to draw or settings of its own: several methods without a
value at one size, no value at all, the settings a title must name, a compare of one pair or none. Each test
builds the matplotlib Figure and reads its texts and limits (tests/pipelines/test_plots_readable.py's way)."""

from __future__ import annotations

import pytest

from pipelines.commands.sweep_plan import configured_experiment
from pipelines.config import load
from pipelines.experiments.compare_plot import compare_figure
from pipelines.experiments.report_plots import OUTCOMES, outcome_figure
from pipelines.experiments.safety_plots import safety_tradeoff_figure
from pipelines.experiments.summary import summarize
from tests.pipelines.test_plots_readable import _drawn, _versus
from tests.pipelines.test_safety_report import _record

TRAVEL = next(o for o in OUTCOMES if o.name == "travel_time")


def _experiment(*sets: str):
    return configured_experiment(load(sets=["sweep.experiment=baselines", *sets]))


def test_methods_without_a_value_at_one_size_share_one_short_note_inside_the_axes():
    """Two columns of one size without success: "straight time_limit=3.0, ORCA time_limit=3.0: no success",
    rotated, rose from the foot of the axes through the title; their markers, in their colours, say which."""
    experiment = _experiment('sweep.vary="env.time_limit=3,40"')
    cells = experiment.cells((3, 4))
    records = [_record(c, i, 1.0, 20, success="=40" in c.method) for c in cells for i in range(2)]
    fig = outcome_figure(experiment, summarize(experiment, cells, records), TRAVEL)
    renderer = _drawn(fig)
    ax = fig.axes[0]
    notes = [t for t in ax.texts if "no success" in t.get_text()]
    assert [t.get_text() for t in notes] == ["no success", "no success"]  # one per crowd size
    frame = ax.get_window_extent(renderer)
    assert all(frame.contains(b.x0, b.y0) and frame.contains(b.x1, b.y1) for b in
               (t.get_window_extent(renderer) for t in notes))  # fmt: skip
    assert ax.get_ylim()[0] < 0.0 < ax.get_ylim()[1]  # the axis from 0: the feet's markers read as no value
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "straight time_limit=3.0 (ours, no success)" in labels


def test_a_bar_plot_with_no_value_at_all_keeps_its_slots_and_shows_no_scale():
    """Every travel time missing: the y axis read 0 to 0.05 s and the two slots sat on the frame's edges."""
    experiment = _experiment("env.time_limit=3")
    cells = experiment.cells((3,))
    records = [_record(c, i, 1.0, 20, success=False) for c in cells for i in range(2)]
    ax = outcome_figure(experiment, summarize(experiment, cells, records), TRAVEL).axes[0]
    assert ax.get_xlim() == (-0.6, 1.6) and list(ax.get_yticks()) == []
    assert [t.get_text() for t in ax.texts] == ["no success", "no success"]


def test_a_title_names_the_predictor_margins_and_mpc_settings_every_column_shares():
    """Table II with constant velocity at d_min 1.0 was titled "Table II: centralized (CMPC) vs distributed
    (DMPC) MPC" alone, beside the paper's squares; table.md said both."""
    experiment = configured_experiment(
        load(sets=["sweep.experiment=table2", "controller.predictor=constant_velocity", "mpc.d_min=1.0"])
    )
    cells = experiment.cells((5, 6))
    summaries = summarize(experiment, cells, [_record(c, i, 1.0, 20) for c in cells for i in range(2)])
    title = outcome_figure(experiment, summaries, TRAVEL).axes[0].get_title().split("\n")
    assert title[1] == "predictor constant_velocity; margins none; MPC d_min=1.0"
    tradeoff = safety_tradeoff_figure(experiment, summaries)
    assert "predictor constant_velocity; margins none; MPC d_min=1.0" in tradeoff.get_suptitle()
    assert tradeoff.axes[0].get_ylim() == (-3.0, 103.0)  # success on its whole scale, not from 27 %
    # the shipped experiment names its own predictor; the baselines predict nothing: no line
    table2 = configured_experiment(load(sets=["sweep.experiment=table2"]))
    cells = table2.cells((5,))
    summaries = summarize(table2, cells, [_record(c, i, 1.0, 20) for c in cells for i in range(2)])
    assert outcome_figure(table2, summaries, TRAVEL).axes[0].get_title().split("\n")[1] == (
        "predictor social_lstm_eth; margins none"
    )
    baselines = _experiment()
    cells = baselines.cells((3,))
    summaries = summarize(baselines, cells, [_record(c, i, 1.0, 20) for c in cells for i in range(2)])
    assert outcome_figure(baselines, summaries, TRAVEL).axes[0].get_title().split("\n")[-2] == (
        "mean over successful episodes"
    )
    assert len(outcome_figure(baselines, summaries, TRAVEL).axes[0].get_title().split("\n")) == 4


def test_compare_says_where_no_pair_completed_and_where_one_did():
    """A method without a travel time in one run vanished from the travel panel, and one pair's change stood
    as a bare point under a legend promising 95 % intervals; "1 shared episodes"."""
    none = _versus(1.0) | {"travel_difference": {"mean": None, "half_width_95": None, "n": 0}}
    one = _versus(1.0) | {"travel_difference": {"mean": 0.8, "half_width_95": None, "n": 1}}
    report = {
        "shared_episodes": 1,
        "runs": [{"label": "a"}, {"label": "b"}],
        "groups": [
            {"method": "CMPC", "humans": 5, "robots": 3, "versus_first": {"b": none}},
            {"method": "CMPC", "humans": 7, "robots": 3, "versus_first": {"b": one}},
        ],
    }
    fig = compare_figure(report)
    travel = fig.axes[-1]
    assert sorted(t.get_text() for t in travel.texts) == ["n = 1", "none completed by both"]
    assert all(not ax.texts for ax in fig.axes[:-1])
    assert fig.get_suptitle() == "Paired on 1 shared episode (crowdmpc compare)"


def _lone(mean: float) -> dict:
    return _versus(1.0) | {"travel_difference": {"mean": mean, "half_width_95": None, "n": 1}}


@pytest.mark.parametrize("sizes", [(5,), (5, 6, 7, 8, 9, 10), tuple(range(3, 15))])
def test_compare_notes_of_methods_at_one_crowd_size_neither_collide_nor_leave_the_panel(sizes):
    """An "n = 1" beside each point ran into the next method's at the same crowd size ("n =n = 1") and the
    last past the panel's right edge; a "none completed by both" at each point's place ran into the next."""
    looks = {"CMPC": _lone(0.5), "DMPC": _lone(1.5), "ORCA": _versus(1.0)}
    none = _versus(1.0) | {"travel_difference": {"mean": None, "half_width_95": None, "n": 0}}
    groups = [
        {"method": m, "humans": h, "robots": 3, "versus_first": {"b": none if (h + k) % 3 == 0 else v}}
        for h in sizes
        for k, (m, v) in enumerate(looks.items())
    ]
    fig = compare_figure({"shared_episodes": 1, "runs": [{"label": "a"}, {"label": "b"}], "groups": groups})
    renderer = _drawn(fig)
    travel = fig.axes[-1]
    texts = [t.get_text() for t in travel.texts]
    boxes = [t.get_window_extent(renderer) for t in travel.texts]
    panel = travel.get_window_extent(renderer)
    for k, box in enumerate(boxes):
        assert panel.x0 <= box.x0 and box.x1 <= panel.x1 and panel.y0 <= box.y0 and box.y1 <= panel.y1
        assert fig.bbox.contains(box.x0, box.y0) and fig.bbox.contains(box.x1, box.y1)
        assert not any(box.overlaps(other) for other in boxes[k + 1 :])
    points = travel.transData.transform([(x, y) for line in travel.get_lines() for x, y in line.get_xydata()
                                         if line.get_transform() == travel.transData])  # fmt: skip
    assert texts.count("n = 1") == len(sizes) and "none completed by both" in texts
    heads = [box for box, t in zip(boxes, texts, strict=True) if t == "n = 1"]
    assert all(box.y0 > points[:, 1].max() for box in heads)  # above every point, in room of their own


def test_a_travel_panel_without_any_pair_keeps_its_zero_line_on_a_scale_of_seconds():
    """`compare full=A short=B` where B's time limit left no episode completed by both: the travel panel had
    no point to scale by, and its y axis ran from 1.32e-17 to 1.46e-17 s, the zero line off it and the open
    markers at a height that read as a change. Its axis now spans a second either side of zero."""
    from pipelines.experiments.compare_plot import compare_figure
    from tests.pipelines.test_plots_readable import _drawn, _report

    report = _report([("orca", 5)])
    report["groups"][0]["versus_first"]["b"]["travel_difference"] = {
        "mean": None,
        "half_width_95": None,
        "n": 0,
    }
    fig = compare_figure(report)
    _drawn(fig)
    travel = fig.axes[-1]
    low, high = travel.get_ylim()
    assert low <= -1.0 and 1.0 <= high and high - low < 10.0
    assert "none completed by both" in [t.get_text() for t in travel.texts]
    for ax in fig.axes[:-1]:  # the rates' panels keep their points' scale
        assert ax.get_ylim()[0] < -5.0


def test_a_title_names_a_team_other_than_the_papers():
    """Table II of two robots (--robots 2) was titled as the paper's, of three: its plots showed no paper
    squares and said nothing of why; table.md said "Robots: 2 per episode". One robot reads "1 robot"; the
    paper's three, or teams that vary (plotted against them), add nothing."""
    table2 = configured_experiment(load(sets=["sweep.experiment=table2"]))
    for team, words in ((2, "; 2 robots"), (1, "; 1 robot"), (3, "")):
        cells = table2.cells((5, 6), n_robots=team)
        summaries = summarize(table2, cells, [_record(c, i, 1.0, 20) for c in cells for i in range(2)])
        line = f"predictor social_lstm_eth; margins none{words}"
        assert outcome_figure(table2, summaries, TRAVEL).axes[0].get_title().split("\n")[1] == line
        assert safety_tradeoff_figure(table2, summaries).get_suptitle().split("\n")[1] == line
    teams = configured_experiment(load(sets=["sweep.experiment=table2", 'sweep.vary="scenario.robots=2,4"']))
    cells = teams.cells((5,))
    summaries = summarize(teams, cells, [_record(c, i, 1.0, 20) for c in cells for i in range(2)])
    title = outcome_figure(teams, summaries, TRAVEL).axes[0].get_title().split("\n")
    assert title[1] == "predictor social_lstm_eth; margins none"


def test_compare_names_under_its_title_what_each_run_ran_with_otherwise():
    """`compare lstm=T2 cv=T2CV --plot`: the figure named the runs by their labels alone, and a PNG of the
    paper's predictor against constant velocity said nothing of the predictor. Under the title each run after
    the first says what differs (two settings named, the rest counted; a setting and its values never parted
    by the wrapping), or that it ran with the first's settings."""
    rows = [
        {"setting": "predictor", "first": '"social_lstm_eth"', "this": '"constant_velocity"'},
        {"setting": "predictor_sha256", "first": f'"{"e" * 64}"', "this": "null"},
        {"setting": "mpc.d_min", "first": "0.8", "this": "1.0"},
    ]
    report = {
        "shared_episodes": 2,
        "runs": [{"label": "lstm"}, {"label": "cv"}, {"label": "again"}],
        "groups": [
            {
                "method": "CMPC",
                "humans": 5,
                "robots": 3,
                "versus_first": {"cv": _versus(1.0), "again": _versus(0.0)},
            }
        ],
        "settings_differ": {"cv": rows, "again": []},
    }
    assert compare_figure(report).get_suptitle().split("\n") == [
        "Paired on 2 shared episodes (crowdmpc compare)",
        "cv against lstm: predictor social_lstm_eth → constant_velocity;",
        f"predictor_sha256 {'e' * 23}… → null; 1 more setting (crowdmpc compare lists them)",
        "again ran with the settings of lstm",
    ]
