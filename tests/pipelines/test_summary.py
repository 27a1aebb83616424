"""The report's statistics beyond tests/pipelines/test_sweep.py's hand values: the Wilson interval at its
edges, Student's t against scipy, a cell's rates and solver figures by hand, and the bold mark."""

from __future__ import annotations

import math

import pytest

from pipelines.errors import PipelineError
from pipelines.experiments.cells import get_experiment
from pipelines.experiments.report import cell_rows
from pipelines.experiments.summary import Rate, paper_figures, summarize_cell, t95, wilson_interval
from pipelines.experiments.tables import _best


@pytest.mark.parametrize("n", [16, 21, 37, 40])
def test_wilson_interval_stays_inside_0_and_1_at_the_extremes(n):
    # At 0 of n the centre and the half width are the same number, z^2/(2n) / (1 + z^2/n), computed two ways:
    # for these n the unclipped lower bound rounds to about -1e-17 (n = 21, 37) and the upper bound at n of n
    # to 1 + 1e-16 (n = 16, 40). The table prints them; a "-0.0" would read as a bug.
    lo, _ = wilson_interval(0, n)
    _, hi = wilson_interval(n, n)
    assert lo == 0.0 and hi == 1.0


def test_wilson_interval_is_exactly_0_and_1_at_the_extremes_for_every_n():
    # 0 of 3 and 0 of 50 left a lower bound of 5.6e-17 (cells.csv: 5.551115123125783e-15 %), 50 of 50 an
    # upper bound a hair below 1: the exact bounds there are 0 and 1.
    assert all(wilson_interval(0, n)[0] == 0.0 for n in range(1, 1001))
    assert all(wilson_interval(n, n)[1] == 1.0 for n in range(1, 1001))


def test_wilson_interval_refuses_a_negative_count():
    with pytest.raises(PipelineError, match="0 <= successes <= n, got -1 of 10"):
        wilson_interval(-1, 10)


@pytest.mark.parametrize("dof", [1, 2, 7, 30, 120, 500, 1000, 1001, 2000, 10**5])
def test_t95_matches_scipy(dof):
    # "Exact for dof <= 1000; beyond, Cornish-Fisher with an error below 3e-9" (t95's docstring): the
    # tolerance 1e-8 would not hold for the expansion below 1000 dof, nor without its 1/dof^2 term
    # (2.8e-6 at 1001 dof).
    stats = pytest.importorskip("scipy.stats")
    assert t95(dof) == pytest.approx(float(stats.t.ppf(0.975, dof)), rel=0, abs=1e-8)


def test_a_rate_over_no_episode_is_nan_not_zero():
    # success_by_scenario has a Rate(0, 0) for a scenario the cell did not run: no figure, not 0 %.
    empty = Rate(0, 0)
    assert math.isnan(empty.percent) and all(math.isnan(x) for x in empty.interval)
    assert Rate(3, 4).percent == 75.0


def _record(
    i: int, *, success: bool, min_distance: float | None, median: float, p95: float, total: float, time_s=20.0
):
    """One circle episode (seed i) of 10 control steps, with the solver figures given."""
    return {
        "scenario": "circle",
        "seed": i,
        "metrics": {
            "success": success,
            "travel_time": time_s if success else None,
            "collision": False,
            "contact": False,
            "discomfort": False,
            "min_distance": min_distance,
            "n_steps": 10,
        },
        "solver": {
            "steps": 10,
            "total_ms": total,
            "median_ms": median,
            "p95_ms": p95,
            "mean_iterations": 2.0,
            "fallback_steps": 0,
        },
    }


def test_a_cells_distance_and_solver_figures_by_hand():
    cell = get_experiment("table2").cells()[0]
    records = [
        _record(0, success=True, min_distance=1.0, median=10.0, p95=20.0, total=100.0),
        _record(1, success=True, min_distance=2.0, median=11.0, p95=30.0, total=110.0),
        _record(2, success=False, min_distance=None, median=30.0, p95=100.0, total=390.0),  # no human near
    ]
    s = summarize_cell(cell, records, None)
    # the mean of the episodes' minima over the episodes that had one: (1 + 2) / 2, the null is no 0 m
    assert s.min_distance_mean == pytest.approx(1.5)
    # the null is inf in the histogram's list, and left out of the median: (1 + 2) / 2, not median(1, 2, inf)
    assert s.min_distances == (1.0, 2.0, math.inf)
    assert s.min_distance_median == pytest.approx(1.5)
    # median of the episodes' medians 10, 11, 30 -> 11 (their mean would be 17)
    assert s.step_median_ms == pytest.approx(11.0)
    # numpy's linear 95th percentile of 20, 30, 100: 30 + (1.9 - 1) x 70 = 93 (the 90th would be 86)
    assert s.step_p95_ms == pytest.approx(93.0)
    # all control-step time over all steps: 600 ms / 30 steps (the mean of the totals would be 200). With 10
    # steps in every episode this is also the mean of the episodes' means, (10 + 11 + 39) / 3: the test
    # below tells the two apart.
    assert s.step_mean_ms == pytest.approx(20.0)
    assert s.success.count == 2 and s.success.n == 3


def test_the_mean_step_time_pools_every_step_of_the_cell():
    """step_mean_ms is all control-step time over all steps, so a long episode weighs by its steps: 10 steps
    of 10 ms (100 ms) and 30 of 30 ms (900 ms) give 1000 ms / 40 steps = 25 ms, not the mean of the episodes'
    means (10 + 30) / 2 = 20 ms."""
    cell = get_experiment("table2").cells()[0]
    short = _record(0, success=True, min_distance=1.0, median=10.0, p95=10.0, total=100.0)
    long = _record(1, success=True, min_distance=1.0, median=30.0, p95=30.0, total=900.0)
    long["solver"]["steps"] = 30
    assert summarize_cell(cell, [short, long], None).step_mean_ms == pytest.approx(25.0)


def test_the_mean_iterations_pool_every_step_of_the_cell():
    """IBR iterations per step are all iterations over all steps, as `simulate` prints them for the same
    episodes: 10 steps at 1 iteration and 30 at 5 give (10 + 150) / 40 = 4, not the mean of the episodes'
    means (1 + 5) / 2 = 3."""
    cell = get_experiment("table2").cells()[0]
    short = _record(0, success=True, min_distance=1.0, median=1.0, p95=1.0, total=10.0)
    long = _record(1, success=True, min_distance=1.0, median=1.0, p95=1.0, total=30.0)
    short["solver"]["mean_iterations"] = 1.0
    long["solver"] |= {"steps": 30, "mean_iterations": 5.0}
    assert summarize_cell(cell, [short, long], None).iterations_mean == pytest.approx(4.0)


def test_the_papers_figures_go_to_the_papers_team_only():
    """The paper's tables are all of PAPER_ROBOTS = 3 robots: a team of 2 or of 4 gets none."""
    table2 = get_experiment("table2")
    three, two, four = (table2.cells(n_robots=m)[0] for m in (3, 2, 4))
    assert (three.method, three.n_humans) == (four.method, four.n_humans) == (two.method, two.n_humans)
    assert paper_figures(table2, three) is table2.paper[(three.method, three.n_humans)]
    assert paper_figures(table2, three) is not None
    assert paper_figures(table2, two) is None
    assert paper_figures(table2, four) is None


def test_cells_csv_gives_the_travel_time_and_its_interval():
    # successes in 18 and 20 s (the failure's time is not counted): mean 19 s; sample sd sqrt(2), standard
    # error 1 s, half width t95(1) x 1 = 12.706 s
    cell = get_experiment("table2").cells()[0]
    records = [
        _record(0, success=True, min_distance=1.0, median=1.0, p95=1.0, total=10.0, time_s=18.0),
        _record(1, success=True, min_distance=1.0, median=1.0, p95=1.0, total=10.0, time_s=20.0),
        _record(2, success=False, min_distance=1.0, median=1.0, p95=1.0, total=10.0),
    ]
    (row,) = cell_rows([summarize_cell(cell, records, None)])
    assert row["travel_time_mean"] == pytest.approx(19.0)
    assert row["travel_time_ci"] == pytest.approx(12.7062, abs=1e-4)


def test_cells_csv_gives_the_iterations_and_the_fallback_rate_apart():
    """Two episodes of 10 steps, 2 IBR iterations a step, 3 and 1 fallback steps: 4 of 20 steps fell back,
    fallback_step_rate 20 %, iterations_mean 2."""
    cell = get_experiment("table2").cells()[0]
    records = [_record(i, success=True, min_distance=1.0, median=1.0, p95=1.0, total=10.0) for i in range(2)]
    records[0]["solver"]["fallback_steps"] = 3
    records[1]["solver"]["fallback_steps"] = 1
    (row,) = cell_rows([summarize_cell(cell, records, None)])
    assert row["iterations_mean"] == pytest.approx(2.0)
    assert row["fallback_step_rate"] == pytest.approx(20.0)


def test_cells_csv_names_the_predictor_a_cell_plans_with():
    """A controller that plans with none (orca, straight) has none in cells.csv, as in its records
    ("predictor": null) and its cell key (orca-none-...): the row named the experiment's --predictor."""
    experiment = get_experiment("controllers").with_predictor("social_lstm_eth")
    records = [_record(0, success=True, min_distance=1.0, median=1.0, p95=1.0, total=10.0)]
    rows = cell_rows([summarize_cell(cell, records, None) for cell in experiment.cells((5,))])
    named = {row["method"]: row["predictor"] for row in rows}
    assert named == {"cmpc": "social_lstm_eth", "dmpc": "social_lstm_eth", "orca": None, "straight": None}
    assert all(("-none-" in row["cell"]) == (row["predictor"] is None) for row in rows)
    # nor a flocking term or a coupling: a reader grouping by flocking counted ORCA among the flocking
    settings = {row["method"]: (row["flocking"], row["coupling"]) for row in rows}
    assert settings == {
        "cmpc": (True, "ibr"),
        "dmpc": (True, "ibr"),
        "orca": (None, None),
        "straight": (None, None),
    }


def test_the_bold_mark_compares_the_printed_values():
    # 75.04 and 75.01 both print as 75.0: a tie, left unmarked; 75.06 prints as 75.1 and wins.
    assert _best([75.04, 75.01], higher_is_better=True) == set()
    assert _best([75.06, 75.01], higher_is_better=True) == {0}
    assert _best([18.96, 19.04], higher_is_better=False) == set()  # travel time: both 19.0
    # a method without a success has no travel time: nothing to beat, and a tie of the others is a tie
    nan = float("nan")
    assert _best([20.0, nan], higher_is_better=False) == set()
    assert _best([20.0, 20.04, nan], higher_is_better=False) == set()
    assert _best([20.0, 21.0, nan], higher_is_better=False) == {0}


def test_a_cells_figures_do_not_depend_on_the_order_its_records_finished():
    """episodes.jsonl holds the episodes in the order the workers finished them: a sweep resumed after Ctrl-C
    wrote a cells.csv whose travel_time_mean was 15.679999999999998 where the uninterrupted sweep's was
    15.680000000000001 (the same episodes, summed in another order)."""
    cell = get_experiment("table2").cells()[0]
    records = [
        _record(i, success=True, min_distance=1.0 + i, median=1.0, p95=1.0, total=10.0, time_s=t)
        for i, t in enumerate((0.1, 0.2, 0.3))
    ]
    forward, backward = (cell_rows([summarize_cell(cell, r, None)]) for r in (records, records[::-1]))
    assert forward == backward


def test_a_travel_time_of_one_success_says_why_it_has_no_interval():
    """The header promises "± the 95% interval of its mean": a lone "25.6" read as a figure without one."""
    from pipelines.experiments.summary import summarize
    from pipelines.experiments.tables import markdown_table

    experiment = get_experiment("table2")
    cmpc, dmpc = experiment.cells((5,))
    one = [_record(0, success=True, min_distance=1.0, median=1.0, p95=1.0, total=10.0, time_s=25.6)]
    one.append(_record(1, success=False, min_distance=1.0, median=1.0, p95=1.0, total=10.0))
    two = [_record(i, success=True, min_distance=1.0, median=1.0, p95=1.0, total=10.0) for i in range(2)]
    records = [r | {"cell": cmpc.key} for r in one] + [r | {"cell": dmpc.key} for r in two]
    table = markdown_table(experiment, summarize(experiment, [cmpc, dmpc], records))
    (row,) = [line for line in table.splitlines() if line.startswith("| Average travel time (s) |")]
    assert row.split(" | ")[1:3] == ["25.6 (1 success)", "**20.0 ± 0.0** |"]  # bold: the shorter
