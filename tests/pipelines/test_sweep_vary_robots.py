"""`sweep --vary scenario.robots=M1,M2`: a column per number of robots beside every method, each the cell
`--robots M` makes."""

from __future__ import annotations

import csv
import json
import pickle

import pytest

from pipelines.cli import main
from pipelines.commands.sweep_plan import configured_experiment
from pipelines.config import load
from pipelines.experiments.cells import get_experiment
from tests.pipelines.test_sweep_vary import SWEEP, _plan


def test_every_method_gets_a_column_per_number_of_robots_each_the_cell_robots_makes(tmp_path, capsys):
    """ORCA and the straight line drive robots too: a column each, where an [mpc] value leaves them one."""
    out = ["--out", str(tmp_path / "sw")]
    varied = _plan(capsys, "--experiment", "controllers", "--vary", "scenario.robots=2,5", *out)
    assert list(varied) == [
        f"{method} robots={m}" for method in ("cmpc", "dmpc", "orca", "straight") for m in (2, 5)
    ]
    for m in (2, 5):
        alone = _plan(capsys, "--experiment", "controllers", "--robots", str(m), *out)
        assert {label: key for label, key in varied.items() if label.endswith(f"={m}")} == {
            f"{label} robots={m}": key for label, key in alone.items()
        }
    assert varied["orca robots=5"] == "orca-none-F-ibr-m=none-paper-visible-h5-r5"


def test_robots_vary_last_in_a_grid_and_keep_the_paper_beside_three():
    """With an [mpc] value: every combination, robots last in the label; the paper's figures stay on the
    columns of Table I's settings, and the summary shows them only beside 3 robots (summary.paper_figures)."""
    from pipelines.experiments.summary import paper_figures

    sets = ["sweep.experiment=table2", 'sweep.vary="mpc.d_min=0.8,0.9;scenario.robots=3,6"']
    experiment = configured_experiment(load(sets=sets))
    assert experiment.method_labels[:4] == (
        "CMPC d_min=0.8 robots=3",
        "CMPC d_min=0.8 robots=6",
        "CMPC d_min=0.9 robots=3",
        "CMPC d_min=0.9 robots=6",
    )
    assert experiment.title.endswith("; d_min = 0.8, 0.9; robots = 3, 6")
    cells = {(c.method, c.n_humans): c for c in experiment.cells((5,), n_robots=4)}
    assert [cells[f"CMPC d_min=0.8 robots={m}", 5].n_robots for m in (3, 6)] == [3, 6]
    paper = get_experiment("table2").paper["CMPC", 5]
    assert paper_figures(experiment, cells["CMPC d_min=0.8 robots=3", 5]) == paper
    assert paper_figures(experiment, cells["CMPC d_min=0.8 robots=6", 5]) is None
    assert paper_figures(experiment, cells["CMPC d_min=0.9 robots=3", 5]) is None  # not Table I's d_min
    # sent to a worker process (spawn) and back, the robots stay the columns' own, read-only
    again = pickle.loads(pickle.dumps(experiment))
    assert again.method_robots == experiment.method_robots
    with pytest.raises(TypeError):
        again.method_robots["CMPC d_min=0.8 robots=3"] = 4  # type: ignore[index]


@pytest.mark.parametrize(
    "options, message",
    [
        (["--vary", "scenario.robots=3,4", "--robots", "5"], "--vary and --robots both set the robots"),
        (["--vary", "scenario.robots=3,0"], "--vary value 0 must be in 1..12, got 0"),
        (["--vary", "scenario.robots=3,13"], "--vary value 13 must be in 1..12, got 13"),
        (["--vary", "scenario.robots=3,2.5"], "--vary value 2.5 must be an integer"),
        (["--vary", "scenario.robots=3,3"], "--vary: value 3 is given more than once"),
        (["--vary", "scenario.robots=3"], "expected scenario.robots=V1,V2,... with at least two values"),
        (
            ["--vary", "scenario.humans=3,4"],
            "the robots (scenario.robots=M1,M2,...), a simulator setting (env.KEY or env.orca.KEY",
        ),
    ],
)
def test_robots_that_cannot_vary_are_one_line(tmp_path, capsys, options, message):
    assert main([*SWEEP, "--experiment", "table2", *options, "--out", str(tmp_path / "sw")]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_a_robots_sweep_reuses_the_plain_sweeps_episodes_and_records_each_cells_team(tmp_path, capsys):
    """The 3-robot columns are the plain sweep's cells: only the 2-robot ones run. cells.csv, episodes.jsonl
    and sweep.json give each cell its own team; the table's note lists them."""
    out = tmp_path / "sw"
    run = ["sweep", "--experiment", "table2", "--predictor", "constant_velocity", "--humans", "3"]
    run += ["--episodes-per-cell", "2", "--backend", "inline", "--no-progress", "--out", str(out)]
    assert main(run) == 0
    assert main([*run, "--vary", "scenario.robots=3,2"]) == 0
    assert "8/8 episodes recorded (4 this run" in capsys.readouterr().err
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    teams = {
        (r["method"], r["key"].split("/")[0].rsplit("-", 1)[1], len(r["metrics"]["path_length"]))
        for r in records
    }
    assert teams == {
        ("CMPC", "r3", 3),
        ("DMPC", "r3", 3),
        ("CMPC robots=2", "r2", 2),
        ("DMPC robots=2", "r2", 2),
    }
    with (out / "cells.csv").open() as f:
        rows = [(row["method"], row["n_robots"]) for row in csv.DictReader(f)]
    assert rows == [
        ("CMPC robots=3", "3"),
        ("CMPC robots=2", "2"),
        ("DMPC robots=3", "3"),
        ("DMPC robots=2", "2"),
    ]
    last = json.loads((out / "sweep.json").read_text())["runs"][-1]
    assert [(c["method"], str(c["n_robots"])) for c in last["cells"]] == rows
    table = (out / "table.md").read_text()
    assert "Robots: 2, 3 per episode (the paper's tables: 3)." in table
    assert "| Metrics \\ Methods | CMPC robots=3 | CMPC robots=2 | DMPC robots=3 | DMPC robots=2 |" in table


def test_the_sweep_notes_a_team_larger_than_the_papers_under_the_per_pair_weight(tmp_path, capsys):
    """simulate's flock note, once per method whose cells have more than 3 robots and flock per pair."""
    out = ["--out", str(tmp_path / "sw")]
    assert main([*SWEEP, "--experiment", "table3", "--vary", "scenario.robots=3,4", *out]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "flocking weight" in line]
    assert notes == [
        "note: method 'F robots=4': 4 robots under the paper's per-pair flocking weight, set for 3; "
        "--set mpc.flocking_weight=per_robot (in docs/examples/many_robots.toml) weighs it per robot"
    ]  # not table3's NF, which does not flock
    per_robot = ["--set", "mpc.flocking_weight=per_robot"]
    assert main([*SWEEP, "--experiment", "table3", "--robots", "4", *per_robot, *out]) == 0
    assert "flocking weight" not in capsys.readouterr().err


def test_one_crowd_size_over_several_teams_plots_each_outcome_against_the_robots(tmp_path):
    """A line per method the columns share ("CMPC robots=3" and "CMPC robots=6" make "CMPC") at x = 3 and
    6 robots (each method shifted by its dodge), the paper's mark at 3 only; files OUTCOME_vs_robots.png."""
    from pipelines.experiments.report import write_report
    from pipelines.experiments.report_plots import OUTCOMES, outcome_figure
    from pipelines.experiments.summary import summarize
    from tests.pipelines.test_small_fixes import EPISODES, _records

    sets = ["sweep.experiment=table2", 'sweep.vary="scenario.robots=3,6"']
    experiment = configured_experiment(load(sets=sets))
    cells = [c for c in experiment.cells() if c.n_humans == 5]
    records = _records(experiment, {(c.method, 5): EPISODES for c in cells})
    names = {p.name for p in write_report(tmp_path, experiment, cells, records).files if p.suffix == ".png"}
    # robot_contact_vs_robots.png only of records that hold the flag, which these synthetic ones do not
    assert {f"{o.name}_vs_robots.png" for o in OUTCOMES if o.name != "robot_contact"} <= names
    assert not any(name.endswith(("_by_method.png", "_vs_humans.png")) for name in names)
    success = next(o for o in OUTCOMES if o.name == "success")
    ax = outcome_figure(experiment, summarize(experiment, cells, records), success).axes[0]
    handles, labels = ax.get_legend_handles_labels()  # an errorbar's handle holds its data line first
    lines = {label: h if hasattr(h, "get_xdata") else h[0] for h, label in zip(handles, labels, strict=True)}
    assert sorted(lines) == ["CMPC (ours)", "CMPC (paper)", "DMPC (ours)", "DMPC (paper)"]
    ours = lines["CMPC (ours)"].get_xdata()
    dodge = ours[0] - 3
    assert list(ours) == [3 + dodge, 6 + dodge] and dodge < 0  # CMPC left of DMPC
    assert list(lines["CMPC (paper)"].get_xdata()) == [3 + dodge]
    assert list(lines["CMPC (ours)"].get_ydata()) == pytest.approx([200 / 3] * 2)  # 2 of 3 succeeded
    assert ax.get_xlabel() == "number of robots (5 humans)" and list(ax.get_xticks()) == [3, 6]


def test_the_control_step_plot_gives_the_median_with_a_bar_up_to_the_p95():
    """Every synthetic episode's step: median 10 ms, p95 20 ms -> each point at 10, its bar from 10 to 20."""
    from pipelines.experiments.report_plots import OUTCOMES, outcome_figure
    from pipelines.experiments.summary import summarize
    from tests.pipelines.test_small_fixes import EPISODES, _records

    experiment = configured_experiment(
        load(sets=["sweep.experiment=table2", 'sweep.vary="scenario.robots=3,6"'])
    )
    cells = [c for c in experiment.cells() if c.n_humans == 5]
    records = _records(experiment, {(c.method, 5): EPISODES for c in cells})
    step = next(o for o in OUTCOMES if o.name == "control_step")
    ax = outcome_figure(experiment, summarize(experiment, cells, records), step).axes[0]
    handles, labels = ax.get_legend_handles_labels()
    assert labels == ["CMPC (ours)", "DMPC (ours)"]  # the paper gives no step time
    for line, _caps, (bars,) in handles:
        assert list(line.get_ydata()) == [10.0, 10.0]
        assert [tuple(seg[:, 1]) for seg in bars.get_segments()] == [(10.0, 20.0)] * 2
    assert "bars up to the p95" in ax.get_title() and ax.get_ylabel() == "Control step (ms)"


def test_success_is_paired_only_with_a_column_of_as_many_robots():
    """A seed's circle crowd depends on the number of robots (crowdsim.scenarios: seed 4, 5 humans, has
    other humans beside 1 robot than beside 3), so "CMPC robots=6" is no pair of "CMPC robots=3": each team
    has its own reference, CMPC of its team, and DMPC is paired with it. Hand-made outcomes, 4 crowds each:
    CMPC robots=3 succeeds on all, DMPC robots=3 fails crowds 0 and 1 (+0 / −2, p = 2 (1/2)^2 = 0.5);
    CMPC robots=6 fails all, DMPC robots=6 succeeds on crowd 3 (+1 / −0, p = 1). Paired with CMPC robots=3,
    CMPC robots=6 read "+0 / −4 (p = 0.12)" and DMPC robots=6 "+0 / −3 (p = 0.25)", losses on crowds they
    never faced."""
    import numpy as np

    from crowdsim.scenarios import make_layout
    from pipelines.experiments.summary import summarize
    from pipelines.experiments.tables import markdown_table
    from tests.pipelines.test_small_fixes import _records

    one, three = (make_layout("circle", 5, m, np.random.default_rng(4)).human_starts for m in (1, 3))
    assert not np.allclose(one, three)
    sets = ["sweep.experiment=table2", 'sweep.vary="scenario.robots=3,6"']
    experiment = configured_experiment(load(sets=sets))
    cells = [c for c in experiment.cells() if c.n_humans == 5]
    won, lost = (True, False, False, False), (False, False, False, False)
    outcomes = {
        ("CMPC robots=3", 5): [won] * 4,
        ("DMPC robots=3", 5): [lost, lost, won, won],
        ("CMPC robots=6", 5): [lost] * 4,
        ("DMPC robots=6", 5): [lost, lost, lost, won],
    }
    table = markdown_table(experiment, summarize(experiment, cells, _records(experiment, outcomes)))
    assert "| Metrics \\ Methods | CMPC robots=3 | CMPC robots=6 | DMPC robots=3 | DMPC robots=6 |" in table
    assert (
        "| Success, paired with the group's first method | reference | reference | +0 / −2 (p = 0.5) "
        "| +1 / −0 (p = 1) |"
    ) in table
    assert (
        "and the first one on the same crowds (as many robots, the same profile and placement) failed / the"
        in table
    )


def test_the_table_bolds_and_pairs_a_column_only_against_its_own_team():
    """Table II at 5 humans, robots 3 and 6: the humans are placed clear of each team, so a 6-robot episode
    is another crowd than the 3-robot one of its seed (circle seed 3 at 7 humans differs already between 2
    and 3 robots). Each team's first column is its reference: 'CMPC robots=6' was paired with 'CMPC
    robots=3' (+0 / −3 on 'the same crowds'), and bold picked the best of all four columns, robots
    mixed."""
    from pipelines.experiments.summary import summarize
    from pipelines.experiments.tables import markdown_table
    from tests.pipelines.test_small_fixes import _records

    experiment = configured_experiment(
        load(sets=["sweep.experiment=table2", 'sweep.vary="scenario.robots=3,6"'])
    )
    cells = [c for c in experiment.cells() if c.n_humans == 5]
    assert [c.method for c in cells] == ["CMPC robots=3", "CMPC robots=6", "DMPC robots=3", "DMPC robots=6"]
    won, lost = (True, False, False, False), (False, False, False, False)
    outcomes = {"CMPC robots=3": [won] * 3, "CMPC robots=6": [lost] * 3}
    outcomes |= {"DMPC robots=3": [won, won, lost], "DMPC robots=6": [won, lost, lost]}
    records = _records(experiment, {(m, 5): episodes for m, episodes in outcomes.items()})
    table = markdown_table(experiment, summarize(experiment, cells, records))
    paired = "| Success, paired with the group's first method |"
    assert f"{paired} reference | reference | +0 / −1 (p = 1) | +1 / −0 (p = 1) |" in table.splitlines()
    success = next(line for line in table.splitlines() if line.startswith("| Success rate (%) |"))
    # CMPC robots=3 (3 of 3) is the best of the 3-robot columns, DMPC robots=6 (1 of 3) of the 6-robot ones
    assert [text.startswith("**") for text in success.split(" | ")[1:]] == [True, False, False, True]
    assert "Bold among the columns of one team" in table
