"""What a sweep reports about itself: honest CPU time, step-time statistics named for what they are, solver
figures only for controllers with a solver, and plots that say what their error bars are."""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest

import pipelines.loop.episode as episode_module
from pipelines.commands.sweep_report import duration
from pipelines.experiments.cells import get_experiment
from pipelines.experiments.report_plots import OUTCOMES, outcome_figure
from pipelines.experiments.summary import summarize
from pipelines.experiments.tables import STEP_TIME_LABEL, markdown_table
from pipelines.experiments.worker import EpisodeWorker

BURN_S = 0.5  # CPU seconds a child process burns
CHILD = f"import time\nt = time.process_time()\nwhile time.process_time() - t < {BURN_S}: pass"


def test_episode_cpu_counts_the_child_processes(monkeypatch):
    """gcc compiling a --jit solver runs as a child process: its CPU is the episode's."""
    real = episode_module.run_episode
    own: list[float] = []

    def with_a_compiler(*args, **kwargs):
        subprocess.run([sys.executable, "-c", CHILD], check=True)
        start = time.process_time()
        result = real(*args, **kwargs)
        own.append(time.process_time() - start)
        return result

    monkeypatch.setattr(episode_module, "run_episode", with_a_compiler)
    task = get_experiment("baselines").tasks(1, humans=(5,))[0]
    outcome = EpisodeWorker().run(task)
    assert outcome.error is None and outcome.record is not None
    # the child's BURN_S plus the episode's own CPU: process_time alone gives only the latter (and a little)
    assert outcome.record["cpu_s"] >= BURN_S + own[0]


@pytest.mark.parametrize(
    ("seconds", "text"),
    [
        (0.0, "0.0 s"),
        (42.04, "42.0 s"),
        (59.9, "59.9 s"),
        (60.0, "1.0 min"),
        (210.0, "3.5 min"),
        (8100, "2.25 h"),
        (59.96, "1.0 min"),  # the unit is chosen on the rounded figure
        (3599.9, "1.00 h"),
        (1e9, "11574.1 days"),
    ],
)
def test_a_cpu_projection_reads_in_a_unit_that_fits(seconds, text):
    assert duration(seconds) == text


def _record(cell, i: int, iterations: float, fallbacks: int) -> dict:
    return {
        "key": f"{cell.key}/{i}",
        "cell": cell.key,
        "method": cell.method,
        "scenario": ("circle", "perpendicular")[i % 2],
        "seed": i // 2,
        "metrics": {"success": True, "travel_time": 18.0, "collision": False, "contact": False}
        | {"discomfort": False, "min_distance": 1.0, "n_steps": 40},
        "solver": {"steps": 40, "total_ms": 80.0, "median_ms": 2.0, "p95_ms": 3.0, "max_ms": 4.0}
        | {"mean_iterations": iterations, "max_iterations": int(iterations), "fallback_steps": fallbacks},
    }


def test_a_controller_without_a_solver_has_no_solver_figures():
    """ORCA reports 0 IBR iterations a step, which is no measurement: n/a, and nan in cells.csv."""
    experiment = get_experiment("controllers").with_predictor("constant_velocity")
    cells = [c for c in experiment.cells((5,)) if c.method in ("orca", "cmpc")]
    records = [
        _record(c, i, 0.0 if c.method == "orca" else 2.0, 0 if c.method == "orca" else 2)
        for c in cells
        for i in range(2)
    ]
    summaries = summarize(experiment, cells, records)
    by_method = {s.cell.method: s for s in summaries}
    assert not by_method["orca"].runs_solver and by_method["cmpc"].runs_solver
    assert by_method["orca"].iterations_mean != by_method["orca"].iterations_mean  # nan
    assert by_method["cmpc"].fallback_step_rate == pytest.approx(5.0)  # 4 of 80 steps
    table = markdown_table(experiment, summaries)
    order = [s.cell.method for s in summaries]
    expected = {"orca": ("n/a", "n/a"), "cmpc": ("2.00", "5.00")}
    iterations = " | ".join(expected[m][0] for m in order)
    fallbacks = " | ".join(expected[m][1] for m in order)
    assert f"| IBR iterations per step (mean) | {iterations} |" in table
    assert f"| Fallback steps (%) | {fallbacks} |" in table
    assert "n/a: a solver's figure for a controller that runs none." in table


def test_a_controller_without_a_solver_that_says_it_fell_back_shows_it():
    """n/a is for a figure a controller has no use for; one that reports fallback steps (0 iterations, 2
    fallbacks in each of 2 episodes of 40 steps: 4 / 80 = 5 %) shows them."""
    experiment = get_experiment("controllers").with_predictor("constant_velocity")
    cells = [c for c in experiment.cells((5,)) if c.method == "orca"]
    summaries = summarize(experiment, cells, [_record(c, i, 0.0, 2) for c in cells for i in range(2)])
    (orca,) = summaries
    assert not orca.runs_solver and orca.fallback_step_rate == pytest.approx(5.0)
    table = markdown_table(experiment, summaries)
    assert "| IBR iterations per step (mean) | n/a |" in table
    assert "| Fallback steps (%) | 5.00 |" in table


def test_the_step_time_row_names_its_statistic():
    """Not "median / p95", which `simulate` and `review` use for the statistic pooled over all steps."""
    table2 = get_experiment("table2")
    cells = table2.cells((5,))
    summaries = summarize(table2, cells, [_record(c, i, 2.0, 0) for c in cells for i in range(2)])
    table = markdown_table(table2, summaries)
    assert f"| {STEP_TIME_LABEL} | 2.00 / 3.00 | 2.00 / 3.00 |" in table
    assert "median of the episodes' medians / p95 of their p95s" in STEP_TIME_LABEL
    assert "n/a" not in table  # every method has a solver: no note either


def test_the_note_says_which_rows_mark_the_better_method():
    """The note read "Bold: the better method at each number of pedestrians", and a 50-episode CMPC/DMPC
    sweep printed contact 0.0 beside 2.0 unmarked: only the paper's four rows are marked."""
    table2 = get_experiment("table2")
    cells = table2.cells((5,))
    records = [_record(c, i, 2.0, 0) for c in cells for i in range(2)]
    records[-1]["metrics"] |= {"collision": True, "contact": True}  # the last method's: worse in both
    table = markdown_table(table2, summarize(table2, cells, records))
    rows = {line.split(" | ")[0].lstrip("| "): line for line in table.splitlines() if line.startswith("| ")}
    assert "**" in rows["Collision rate (%)"] and "**" not in rows["Contact rate (%) (< 0.6 m)"]
    assert (
        "Bold: the better method at each number of pedestrians, in the paper's four rows (success, " in table
    )


@pytest.mark.parametrize(
    ("outcome", "interval"),
    [("success", "95% Wilson interval"), ("travel_time", "95% Student's t interval of the mean")],
)
def test_plots_across_crowd_sizes_say_what_their_error_bars_are(outcome, interval):
    table2 = get_experiment("table2")
    cells = table2.cells((5, 6))
    summaries = summarize(table2, cells, [_record(c, i, 2.0, 0) for c in cells for i in range(3)])
    (chosen,) = [o for o in OUTCOMES if o.name == outcome]
    ax = outcome_figure(table2, summaries, chosen).axes[0]
    assert ax.get_xlabel() == "number of humans"
    assert f"error bars: our {interval}" in ax.get_title()


def test_methods_with_equal_rates_stay_apart_across_crowd_sizes():
    """`sweep --experiment controllers --humans 5,7,20 --episodes-per-cell 2`: dmpc, orca and straight all
    succeeded in every episode, and their lines, points and error bars lay on top of each other: the plot
    showed straight's and cmpc's alone while its legend named four methods. Each method is shifted a little
    along x now (the ticks stay on the crowd sizes)."""
    experiment = get_experiment("controllers").with_predictor("constant_velocity")
    cells = experiment.cells((5, 7, 20))
    summaries = summarize(experiment, cells, [_record(c, i, 2.0, 0) for c in cells for i in range(2)])
    success = next(o for o in OUTCOMES if o.name == "success")
    ax = outcome_figure(experiment, summaries, success).axes[0]
    points = [tuple(c.lines[0].get_xdata()) for c in ax.containers]
    assert len(points) == len(set(points)) == len(experiment.method_labels)
    for xs in points:
        assert np.allclose(xs, (5, 7, 20), atol=0.25)
    assert list(ax.get_xticks()) == [5, 7, 20]


def test_a_travel_time_axis_shows_no_negative_times():
    """Two successes of 10 and 20 s: the Student's t interval of the mean, 15 +- 63.5 s, reached -48 s, and
    the axis went down to it."""
    experiment = get_experiment("controllers").with_predictor("constant_velocity")
    cells = experiment.cells((5, 7))
    records = [_record(c, i, 2.0, 0) for c in cells for i in range(2)]
    for k, record in enumerate(records):
        record["metrics"]["travel_time"] = 10.0 + 10.0 * (k % 2)
    summaries = summarize(experiment, cells, records)
    travel = next(o for o in OUTCOMES if o.name == "travel_time")
    ax = outcome_figure(experiment, summaries, travel).axes[0]
    bottom, top = ax.get_ylim()
    assert bottom == pytest.approx(-0.015 * top)  # 0 s, with room for a marker standing on it
    assert ax.get_title().endswith("error bars: our 95% Student's t interval of the mean, cut at 0 s")


def test_a_legend_of_many_methods_stands_beside_the_plot():
    """The safety experiment at 5 and 7 humans: a legend of 16 methods, put where matplotlib found the
    least data, covered the middle of success_vs_humans.png. Past 8 entries it stands beside the axes; Table
    II's four stand under them (inside, they covered its points at 0 %), on a figure made taller for them."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    success = next(o for o in OUTCOMES if o.name == "success")
    for name, beside in (("safety", True), ("table2", False)):
        experiment = get_experiment(name)
        cells = experiment.cells((5, 7))
        summaries = summarize(experiment, cells, [_record(c, i, 2.0, 0) for c in cells for i in range(2)])
        fig = outcome_figure(experiment, summaries, success)
        FigureCanvasAgg(fig).draw()
        (ax,) = fig.axes
        legend = ax.get_legend() if beside else fig.legends[0]
        box, frame = legend.get_window_extent(), ax.get_window_extent()
        assert not box.overlaps(frame) and fig.bbox.contains(box.x1 - 1, box.y0 + 1)
        assert len(legend.get_texts()) == len(experiment.method_labels) * (1 if beside else 2)  # + paper's
        if beside:
            assert box.x0 > frame.x1
        else:
            assert box.y1 < frame.y0 and tuple(fig.get_size_inches()) == (6.4, 4.4 + 2 * 0.22)


def _touching(cells, touched: dict[str, list[bool] | None]) -> list[dict]:
    """Records of ``cells``, four each, whose ``robot_contact`` is ``touched[method]`` episode by episode
    (None: records from before the flag, which have none)."""
    records = []
    for c in cells:
        for i in range(4):
            record = _record(c, i, 2.0, 0) | {"n_humans": c.n_humans, "wall_s": 1.0}
            if touched[c.method] is not None:
                record["metrics"]["robot_contact"] = touched[c.method][i]
            records.append(record)
    return records


def test_robot_contact_is_plotted_beside_the_other_safety_rates(tmp_path):
    """Robots touching each other (``robot_contact``, not a metric of the paper) was in cells.csv and
    table.md but in no plot, where collision, contact and discomfort each have one. orca touched in 1 of 4
    episodes (25 %), straight in 3 of 4 (75 %); cmpc's records predate the flag: no bar, said so, as the
    table's "—"."""
    from pipelines.experiments.report import write_report
    from pipelines.experiments.summary import wilson_interval

    experiment = get_experiment("controllers").with_predictor("constant_velocity")
    cells = [c for c in experiment.cells((5,)) if c.method in ("cmpc", "orca", "straight")]
    touched = {"orca": [True, False, False, False], "straight": [True, True, True, False], "cmpc": None}
    records = _touching(cells, touched)
    report = write_report(tmp_path, experiment, cells, records)
    assert "robot_contact_by_method.png" in {p.name for p in report.files}
    assert (tmp_path / "robot_contact_by_method.png").read_bytes().startswith(b"\x89PNG")
    summaries = summarize(experiment, cells, records)
    (outcome,) = [o for o in OUTCOMES if o.name == "robot_contact"]
    ax = outcome_figure(experiment, summaries, outcome).axes[0]
    methods = [t.get_text() for t in ax.get_xticklabels()]
    assert methods == ["cmpc", "orca", "straight"]
    from matplotlib.container import BarContainer

    (bars,) = [c for c in ax.containers if isinstance(c, BarContainer)]
    heights = [bar.get_height() for bar in bars]
    assert np.isnan(heights[0]) and heights[1:] == [25.0, 75.0]
    # the error bars: each rate's 95% Wilson interval
    segments = bars.errorbar.lines[2][0].get_segments()
    for k, hits in ((1, 1), (2, 3)):
        low, high = (100.0 * b for b in wilson_interval(hits, 4))
        assert segments[k][:, 1] == pytest.approx([low, high])
    assert "not in the paper" in ax.get_ylabel() and "not in the paper" in ax.get_title()
    assert "not recorded" in [t.get_text() for t in ax.texts]
    # across crowd sizes: a line per method, cmpc's named as not recorded
    cells = [c for c in experiment.cells((5, 7)) if c.method in ("cmpc", "orca", "straight")]
    summaries = summarize(experiment, cells, _touching(cells, touched))
    ax = outcome_figure(experiment, summaries, outcome).axes[0]
    lines = {c.get_label(): c.lines[0].get_ydata() for c in ax.containers}
    assert list(lines["orca (ours)"]) == [25.0, 25.0] and list(lines["straight (ours)"]) == [75.0, 75.0]
    assert np.isnan(lines["cmpc (ours, not recorded)"]).all()


def test_robot_contact_has_no_plot_with_one_robot_or_without_its_records(tmp_path):
    """One robot cannot touch another, and records from before the flag do not hold it: no plot of nothing."""
    from pipelines.experiments.report import write_report

    experiment = get_experiment("controllers").with_predictor("constant_velocity")
    flagged = {"cmpc": [False] * 4, "dmpc": [False] * 4, "orca": [True] * 4, "straight": [False] * 4}
    for n_robots, touched in ((1, flagged), (3, dict.fromkeys(flagged))):
        cells = experiment.cells((5,), n_robots=n_robots)
        (tmp_path / str(n_robots)).mkdir()
        report = write_report(tmp_path / str(n_robots), experiment, cells, _touching(cells, touched))
        assert "robot_contact_by_method.png" not in {p.name for p in report.files}
        assert "collision_by_method.png" in {p.name for p in report.files}


# A notebook's session: its own backend (Jupyter's inline one; "svg" stands for it here) and a figure open.
_USER_SESSION = """
import matplotlib
matplotlib.use("svg")
import matplotlib.pyplot as plt
from pathlib import Path
import sys
sys.path.insert(0, {tests!r})
from test_sweep_reporting import _record
from pipelines.experiments.cells import get_experiment
from pipelines.experiments.report import write_report
from pipelines.experiments.report_plots import OUTCOMES, outcome_figure
from pipelines.experiments.safety_plots import min_distance_hist_figure, safety_tradeoff_figure
from pipelines.experiments.summary import summarize

mine = plt.figure()
experiment = get_experiment("controllers").with_predictor("constant_velocity")
cells = experiment.cells((5,))
records = [_record(c, i, 1.0, 0) | {{"n_humans": 5, "wall_s": 1.0}} for c in cells for i in range(2)]
summaries = summarize(experiment, cells, records)
figures = [outcome_figure(experiment, summaries, o) for o in OUTCOMES]
figures += [min_distance_hist_figure(experiment, summaries), safety_tradeoff_figure(experiment, summaries)]
report = write_report(Path({out!r}), experiment, cells, records)
print(matplotlib.get_backend(), plt.get_fignums() == [mine.number], len(report.files))
"""


def test_a_report_leaves_the_callers_matplotlib_alone(tmp_path):
    """A sweep's report, written from a notebook, switched the whole process to the Agg backend
    (``matplotlib.use("Agg")``): the notebook's inline figures stopped showing. Its figures also went into
    pyplot's list of open figures (``*_figure`` ones stayed there, 7 a report). The report's figures are
    ``matplotlib.figure.Figure``s now, as crowdsim.plotting's are: no backend chosen, no pyplot state."""
    from pathlib import Path

    script = _USER_SESSION.format(tests=str(Path(__file__).parent), out=str(tmp_path))
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["svg", "True", "12"]


def test_bars_of_many_methods_keep_their_labels_apart():
    """--vary with 12 values gives table2 24 bars at one crowd size: on the usual 6.4 in their labels, slanted
    at 30 degrees, lay 0.1 in apart and wrote over each other. The figure widens instead; Table II's stays."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from pipelines.commands.sweep_plan import configured_experiment
    from pipelines.config import load

    values = ",".join(str(v) for v in range(1, 13))
    varied = configured_experiment(
        load(sets=["sweep.experiment=table2", f'sweep.vary="mpc.w_goal={values}"'])
    )
    success = next(o for o in OUTCOMES if o.name == "success")
    for experiment, width in ((varied, None), (get_experiment("table2"), 6.4)):
        cells = experiment.cells((5,))
        summaries = summarize(experiment, cells, [_record(c, i, 2.0, 0) for c in cells for i in range(2)])
        fig = outcome_figure(experiment, summaries, success)
        FigureCanvasAgg(fig).draw()
        ax = fig.axes[0]
        per_bar = ax.get_position().width * fig.get_size_inches()[0] / len(experiment.method_labels)
        assert per_bar >= 0.34 if width is None else fig.get_size_inches()[0] == width


def test_the_note_of_episodes_not_counted_names_at_most_eight_cells():
    """A sweep stopped early has every cell short: the note names eight and counts the rest; a cell fully
    recorded is not named, and a plan fully recorded has no note."""
    import types

    from pipelines.commands.sweep_table_notes import not_counted_note

    cells = tuple(types.SimpleNamespace(key=f"c{i}", method=f"M{i}", n_humans=5) for i in range(11))
    tasks = [types.SimpleNamespace(cell=c) for c in cells for _ in range(4)]
    recorded = {"c0": 4, "c1": 3}
    note = not_counted_note(cells, tasks, recorded)
    assert note.startswith(
        "Not counted, planned episodes not recorded: M1 at 5 humans 1 of 4; M2 at 5 humans"
    )
    assert (
        "M0 " not in note and "M8 at" in note and "M9" not in note and "; 2 more cells (each raised" in note
    )
    assert not_counted_note(cells, tasks, {c.key: 4 for c in cells}) == ""
