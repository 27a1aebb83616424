"""``sweep --vary mpc.KEY=V1,V2`` ([sweep] vary): a column per value of one [mpc] setting, each the cell
``--set mpc.KEY=V`` makes, Table I's value the cell of a sweep without it."""

import csv
import json

import pytest

from pipelines.cli import main
from pipelines.commands.sweep_plan import configured_experiment
from pipelines.config import load
from pipelines.experiments.cells import get_experiment

SWEEP = ["sweep", "--humans", "5", "--episodes-per-cell", "2", "--dry-run"]


def _plan(capsys, *options: str) -> dict[str, str]:
    """The dry run's cells: method label -> cell key."""
    assert main([*SWEEP, *options]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()[1:]]
    return {" ".join(row[:-3]): row[-1] for row in rows}


def test_a_column_per_value_each_the_cell_set_makes_table_is_value_the_plain_cell(tmp_path, capsys):
    out = ["--out", str(tmp_path / "sw")]
    varied = _plan(capsys, "--experiment", "table2", "--vary", "mpc.d_min=0.8,1.2", *out)
    assert list(varied) == ["CMPC d_min=0.8", "CMPC d_min=1.2", "DMPC d_min=0.8", "DMPC d_min=1.2"]
    plain = _plan(capsys, "--experiment", "table2", *out)
    assert varied["CMPC d_min=0.8"] == plain["CMPC"]  # Table I's 0.8: a sweep's cell without --vary
    assert (
        varied["DMPC d_min=1.2"]
        == _plan(capsys, "--experiment", "table2", "--set", "mpc.d_min=1.2", *out)["DMPC"]
    )


def test_the_varied_key_keeps_its_place_among_the_other_mpc_settings(tmp_path, capsys):
    """Cell keys list the [mpc] overrides in the table's order: a varied value given before or after other
    settings must make the key --set makes, or the sweep would not find the episodes already run."""
    out = ["--out", str(tmp_path / "sw")]
    common = ["--experiment", "table2", "--set", "mpc.horizon=8", "--set", "mpc.j_max=5", *out]
    # w_coll and d_min come between horizon and j_max in [mpc]
    for key, value, cell in (
        ("w_coll", "1e5", "horizon=8-w_coll=100000.0-j_max=5"),
        ("d_min", "1.0", "horizon=8-d_min=1.0-j_max=5"),
    ):
        default = str(load().default("mpc", key))
        varied = _plan(capsys, *common, "--vary", f"mpc.{key}={default},{value}")
        alone = _plan(capsys, *common, "--set", f"mpc.{key}={value}")
        assert varied[f"CMPC {key}={float(value)}"] == alone["CMPC"]
        assert alone["CMPC"] == f"cmpc-social_lstm_eth-F-ibr-{cell}-m=none-paper-visible-h5-r3"


def test_methods_that_plan_with_no_predictor_keep_one_column_and_the_paper_stays_on_table_is_columns():
    cfg = load(sets=["sweep.experiment=controllers", 'sweep.vary="mpc.horizon=6,8"'])
    labels = configured_experiment(cfg).method_labels
    assert labels == (
        "cmpc horizon=6",
        "cmpc horizon=8",
        "dmpc horizon=6",
        "dmpc horizon=8",
        "orca",
        "straight",
    )
    cfg = load(sets=["sweep.experiment=table2", 'sweep.vary="mpc.d_min=1.0,0.8"'])
    experiment = configured_experiment(cfg)
    assert experiment.title.endswith("; d_min = 1.0, 0.8")
    assert {label for label, _ in experiment.paper} == {"CMPC d_min=0.8", "DMPC d_min=0.8"}
    assert experiment.paper["CMPC d_min=0.8", 5] == get_experiment("table2").paper["CMPC", 5]


@pytest.mark.parametrize(
    "options, message",
    [
        (
            ["--vary", "mpc.d_min=1.0"],
            "--vary 'mpc.d_min=1.0': expected mpc.d_min=V1,V2,... with at least two",
        ),
        (["--vary", "mpc.d_min=1.0,1.0"], "--vary: value 1.0 is given more than once"),
        (
            ["--vary", "mpc.w_coll=1e5,1e6,100000"],
            "--vary: value 100000 is given more than once (1e5 again: both 100000.0)",
        ),
        (["--vary", "mpc.d_min=1.0,abc"], "--vary value abc must be a finite number, got 'abc'"),
        (["--vary", "mpc.horizon=6,8.5"], "--vary value 8.5 must be an integer >= 1, got 8.5"),
        (["--vary", "mpc.dmin=1,2"], "--vary 'mpc.dmin=1,2': unknown key (did you mean 'd_min'?)"),
        (
            ["--vary", "env.dt=0.1,0.2"],
            "--vary 'env.dt=0.1,0.2': only an [mpc] setting (mpc.KEY=V1,V2,...), the margins",
        ),
        (["--vary", "mpc.jit=true,false"], "--vary: a sweep compiles by [sweep] jit"),
        (
            ["--vary", "mpc.d_min=1,2", "--set", "mpc.d_min=1.5"],
            "--vary and --set mpc.d_min both set mpc.d_min",
        ),
        (["--vary", "nothing"], "--vary must read mpc.KEY=V1,V2,..., got 'nothing'"),
        (  # --set's null unsets a key: no column's value
            ["--vary", "simulate.sensor_range=null,3"],
            "--vary value null: a column needs a value; null unsets only in --set",
        ),
        (
            ["--vary", "mpc.d_min=0.5,1.0"],
            "method 'CMPC d_min=0.5' of experiment 'table2': the MPC's d_min 0.5 m",
        ),
        (  # the NLP's bounds, as the NLP checks them (a sweep folder recorded beyond them reads back)
            ["--vary", "mpc.rho=0.5,2000"],
            "--vary: method 'CMPC rho=2000.0' of experiment 'table2': rho must be at most 1000 s^2, got "
            "2000.0",
        ),
        (
            ["--margins", "conformal:0.1", "--vary", "mpc.horizon=4,6"],
            "method 'CMPC horizon=6' of experiment 'table2': the closed-loop calibration of",
        ),
        (
            ["--experiment", "baselines", "--vary", "mpc.d_min=1,2"],
            "--vary: the methods of experiment 'baselines' ('straight', 'ORCA') plan with no predictor",
        ),
        (
            ["--experiment", "table3", "--vary", "mpc.w_floc=0,10"],
            "--vary: experiment 'table3' compares flocking on and off; w_floc = 0 turns it off",
        ),
        (
            ["--experiment", "coupling", "--vary", "mpc.coupled_mode=exact,first_order"],
            "--vary: method 'NLP exact' of experiment 'coupling' sets coupled_mode = 'exact' itself",
        ),
    ],
)
def test_a_vary_that_cannot_apply_is_one_line(tmp_path, capsys, options, message):
    experiment = [] if "--experiment" in options else ["--experiment", "table2"]
    assert main([*SWEEP, *experiment, *options, "--out", str(tmp_path / "sw")]) != 0
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "sw").exists()


def test_the_margins_vary_each_the_cell_margins_makes_fixed_margins_keeping_their_commas(tmp_path, capsys):
    out = ["--out", str(tmp_path / "sw")]
    margins = "none,conformal:0.1,fixed:0.1,0.1,0.1,0.1"
    varied = _plan(capsys, "--experiment", "table2", "--vary", f"controller.margins={margins}", *out)
    assert list(varied)[:3] == [
        "CMPC margins=none",
        "CMPC margins=cp0.1",
        "CMPC margins=fixed0.1_0.1_0.1_0.1",
    ]
    for value, column in (("conformal:0.1", "cp0.1"), ("fixed:0.1,0.1,0.1,0.1", "fixed0.1_0.1_0.1_0.1")):
        alone = _plan(capsys, "--experiment", "table2", "--margins", value, *out)
        assert varied[f"DMPC margins={column}"] == alone["DMPC"]
    assert varied["CMPC margins=none"] == _plan(capsys, "--experiment", "table2", *out)["CMPC"]
    cfg = load(sets=["sweep.experiment=table2", 'sweep.vary="controller.margins=conformal:0.1,none"'])
    experiment = configured_experiment(cfg)
    assert {label for label, _ in experiment.paper} == {"CMPC margins=none", "DMPC margins=none"}


@pytest.mark.parametrize(
    "options, message",
    [
        (
            ["--experiment", "safety", "--vary", "controller.margins=none,conformal"],
            "--vary: experiment 'safety' fixes each method's margins; they do not vary",
        ),
        (
            ["--experiment", "table2", "--vary", "controller.margins=none,bogus"],
            "--vary value bogus: bad margins 'bogus'; expected none",
        ),
        (
            [
                "--experiment",
                "table2",
                "--vary",
                "controller.margins=none,conformal",
                "--margins",
                "conformal",
            ],
            "--vary and --margins both set the margins: give them once",
        ),
        (
            ["--experiment", "table2", "--vary", "controller.margins=conformal:0.1,conformal:0.10"],
            "--vary: value conformal:0.10 is given more than once",
        ),
    ],
)
def test_margins_that_cannot_vary_are_one_line(tmp_path, capsys, options, message):
    assert main([*SWEEP, *options, "--out", str(tmp_path / "sw")]) != 0
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_a_method_without_flocking_keeps_one_column_when_the_flocking_term_varies():
    """table3's NF plans without Eq. 15: a column per w_floc ran the same episodes again under new keys."""
    cfg = load(sets=["sweep.experiment=table3", 'sweep.vary="mpc.w_floc=5,10"'])
    experiment = configured_experiment(cfg)
    assert experiment.method_labels == ("F w_floc=5.0", "F w_floc=10.0", "NF")
    assert dict(experiment.methods)["NF"] == dict(get_experiment("table3").methods)["NF"]


def test_a_set_flocking_key_leaves_the_method_without_flocking_alone():
    """--set mpc.w_floc=5 keyed table3's NF cell with w_floc=5 though NF plans with w_floc = 0: the same
    episodes ran again under a new key, and never matched the sweep without --set."""
    for setting in ("mpc.w_floc=5", "mpc.d_flock=1.5", 'mpc.flocking_weight="per_robot"'):
        experiment = configured_experiment(load(sets=["sweep.experiment=table3", setting]))
        methods = dict(experiment.methods)
        assert methods["NF"] == dict(get_experiment("table3").methods)["NF"], setting
        key = setting.split("=")[0].split(".")[1]
        assert key in dict(methods["F"].mpc_overrides), setting


def test_a_flocking_key_for_methods_that_never_flock_is_one_line(tmp_path, capsys, monkeypatch):
    from pipelines.experiments.cells import EXPERIMENTS, Experiment

    nf = Experiment("nf_only", "NF only", (("NF", dict(get_experiment("table3").methods)["NF"]),), (3,))
    monkeypatch.setitem(EXPERIMENTS, "nf_only", nf)
    code = main(["sweep", "--experiment", "nf_only", "--set", "mpc.w_floc=5", "--out", str(tmp_path / "s")])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert "experiment 'nf_only' plan without the flocking term (NF), which w_floc shapes" in err


def test_cells_csv_gives_each_cell_its_planned_value_and_none_to_a_controller_without_an_mpc():
    from pipelines.experiments.report import mpc_columns

    cfg = load(sets=["sweep.experiment=table3", 'sweep.vary="mpc.w_floc=5,10"', "sweep.humans=[3]"])
    cells = configured_experiment(cfg).cells((3,), 3)
    # NF plans with w_floc = 0 whatever the sweep varies; Table I's 10 is no override of its cell
    assert [(c.method, mpc_columns(cells)[c.key]) for c in cells] == [
        ("F w_floc=5.0", {"mpc.w_floc": 5.0}),
        ("F w_floc=10.0", {"mpc.w_floc": 10.0}),
        ("NF", {"mpc.w_floc": 0.0}),
    ]
    cfg = load(sets=["sweep.experiment=controllers", 'sweep.controllers=["cmpc", "orca"]', "mpc.horizon=6"])
    cells = configured_experiment(cfg).cells((3,), 3)
    assert [mpc_columns(cells)[c.key] for c in cells] == [{"mpc.horizon": 6}, {"mpc.horizon": None}]
    table_i = mpc_columns(get_experiment("table2").cells((3,), 3))
    assert list(table_i.values()) == [{}, {}]  # Table I's settings: no column


def test_vary_again_makes_a_grid_each_cell_the_one_the_options_make(tmp_path, capsys):
    """Two settings: a column per combination, margins then [mpc] values in the label, and each cell the one
    --set and --margins make; two [mpc] keys each in its place among a set one."""
    out = ["--out", str(tmp_path / "sw")]
    grid = ["--vary", "mpc.d_min=0.8,0.9", "--vary", "controller.margins=none,conformal:0.1"]
    varied = _plan(capsys, "--experiment", "table2", *grid, *out)
    assert list(varied)[:4] == [
        "CMPC margins=none d_min=0.8",
        "CMPC margins=none d_min=0.9",
        "CMPC margins=cp0.1 d_min=0.8",
        "CMPC margins=cp0.1 d_min=0.9",
    ]
    alone = _plan(
        capsys, "--experiment", "table2", "--set", "mpc.d_min=0.9", "--margins", "conformal:0.1", *out
    )
    assert varied["DMPC margins=cp0.1 d_min=0.9"] == alone["DMPC"]
    common = ["--experiment", "table2", "--set", "mpc.w_coll=1e5", *out]
    two = _plan(capsys, *common, "--vary", "mpc.d_min=0.8,0.9", "--vary", "mpc.horizon=4,3")
    both = _plan(capsys, *common, "--set", "mpc.horizon=3", "--set", "mpc.d_min=0.9")
    assert two["CMPC horizon=3 d_min=0.9"] == both["CMPC"]  # labelled in the [mpc] table's order too
    assert (
        both["CMPC"]
        == "cmpc-social_lstm_eth-F-ibr-horizon=3-w_coll=100000.0-d_min=0.9-m=none-paper-visible-h5-r3"
    )


@pytest.mark.parametrize(
    "options, message",
    [
        (["--vary", "mpc.d_min=0.8,0.9", "--vary", "mpc.d_min=1.0,1.1"], "--vary: mpc.d_min varies twice"),
        (
            ["--vary", "mpc.d_min=0.8,0.85,0.9,0.95", "--vary", "mpc.horizon=2,3,4,5"],
            "--vary: 4 x 4 = 16 columns per method; at most 12",
        ),
    ],
)
def test_a_grid_that_cannot_be_is_one_line(tmp_path, capsys, options, message):
    assert main([*SWEEP, "--experiment", "table2", *options, "--out", str(tmp_path / "sw")]) != 0
    assert message in capsys.readouterr().err


def test_a_config_files_vary_is_named_by_the_file(tmp_path, capsys):
    config = tmp_path / "run.toml"
    config.write_text('[sweep]\nexperiment = "table2"\nvary = "mpc.horizon=6,x"\n')
    assert main(["--config", str(config), *SWEEP, "--out", str(tmp_path / "sw")]) != 0
    assert f"{config}: sweep.vary value x must be an integer" in capsys.readouterr().err


def test_a_varied_sweep_reuses_the_episodes_of_table_is_value_and_runs_the_others(tmp_path, capsys):
    out = tmp_path / "sw"
    run = ["sweep", "--experiment", "table2", "--predictor", "constant_velocity", "--humans", "3"]
    run += ["--episodes-per-cell", "2", "--backend", "inline", "--no-progress", "--out", str(out)]
    assert main(run) == 0
    assert main([*run, "--vary", "mpc.d_min=0.8,1.0"]) == 0
    err = capsys.readouterr().err
    assert "8/8 episodes recorded (4 this run" in err
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert sorted({r["method"] for r in records}) == ["CMPC", "CMPC d_min=1.0", "DMPC", "DMPC d_min=1.0"]
    assert {r["config"]["mpc"]["d_min"] for r in records if r["method"].endswith("1.0")} == {1.0}
    table = (out / "table.md").read_text()
    assert (
        "| Metrics \\ Methods | CMPC d_min=0.8 | CMPC d_min=1.0 | DMPC d_min=0.8 | DMPC d_min=1.0 |" in table
    )
    # episodes.csv names each episode by its column, as cells.csv does, whichever run recorded it
    with (out / "episodes.csv").open() as f:
        methods = [row["method"] for row in csv.DictReader(f)]
    assert (
        methods
        == ["CMPC d_min=0.8"] * 2 + ["CMPC d_min=1.0"] * 2 + ["DMPC d_min=0.8"] * 2 + ["DMPC d_min=1.0"] * 2
    )
    # cells.csv gives the value a column of its own, Table I's 0.8 where the cell adds no override
    with (out / "cells.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [(row["method"], row["mpc.d_min"]) for row in rows] == [
        ("CMPC d_min=0.8", "0.8"),
        ("CMPC d_min=1.0", "1.0"),
        ("DMPC d_min=0.8", "0.8"),
        ("DMPC d_min=1.0", "1.0"),
    ]
    assert list(rows[0]).index("mpc.d_min") == list(rows[0]).index("cell") - 1


def test_a_float_column_is_labelled_as_config_show_writes_the_value(tmp_path, capsys):
    """str(1e7) is 10000000.0: w_coll's columns read as counts of zeros; config show writes 1e7."""
    out = ["--out", str(tmp_path / "sw")]
    varied = _plan(capsys, "--experiment", "table2", "--vary", "mpc.w_coll=1e6,1e7,1e8", *out)
    assert list(varied)[:3] == ["CMPC w_coll=1e6", "CMPC w_coll=1e7", "CMPC w_coll=1e8"]
    assert varied["CMPC w_coll=1e8"].startswith("cmpc-social_lstm_eth-F-ibr-w_coll=100000000.0-")  # keys kept


def test_the_dry_run_lines_up_labels_longer_than_the_paper_methods(tmp_path, capsys):
    options = ["--experiment", "sensing", "--vary", "mpc.horizon=4,3", "--out", str(tmp_path / "sw")]
    assert main([*SWEEP, *options]) == 0
    lines = capsys.readouterr().out.splitlines()[1:]
    assert len({line.index(" humans ") for line in lines}) == 1, lines  # '3 m untracked horizon=4' is 23


def test_report_only_names_the_columns_it_has_no_episode_of(tmp_path, capsys):
    """A value added to --vary and reported before it ran: its columns vanished from the table silently."""
    out = tmp_path / "sw"
    run = ["sweep", "--experiment", "table2", "--predictor", "constant_velocity", "--humans", "3"]
    run += ["--episodes-per-cell", "2", "--backend", "inline", "--no-progress", "--out", str(out)]
    assert main(run) == 0
    capsys.readouterr()
    assert main([*run, "--vary", "mpc.horizon=4,3", "--report-only"]) == 0
    err = capsys.readouterr().err
    assert (
        "note: --report-only: no episode of 2 planned cells, left out of the table: 'CMPC horizon=3' "
        "(3 humans), 'DMPC horizon=3' (3 humans); run the sweep without --report-only to run them" in err
    )
    assert main([*run, "--report-only"]) == 0
    assert "no episode of" not in capsys.readouterr().err


def test_a_column_whose_humans_cannot_be_placed_is_refused_before_any_episode(tmp_path, capsys):
    """At a 30 m spawn separation no circle of 7 humans fits the arena: the sweep recorded each such episode's
    traceback in errors.jsonl and tabled the perpendicular ones alone, as if the column had run."""
    out = tmp_path / "sw"
    sweep = ["sweep", "--experiment", "controllers", "--controllers", "straight", "--humans", "7",
             "--episodes-per-cell", "4", "--backend", "inline", "--no-progress",
             "--out", str(out)]  # fmt: skip
    for dry in (["--dry-run"], []):
        assert main([*sweep, *dry, "--vary", "env.spawn_separation=0.1,30"]) == 2
        err = capsys.readouterr().err
        assert err.startswith(
            "crowdmpc sweep: error: cell 'straight spawn_separation=30.0' at 7 humans, crowd orca: the "
            "humans cannot be placed for any of its first 2 circle episodes: could not place human 1 of "
            "n_humans=7"
        )
        assert not out.exists()
    assert main([*sweep, "--vary", "env.spawn_separation=0.1,0.5"]) == 0
    assert not (out / "errors.jsonl").exists()


def test_a_simulator_value_the_profile_has_already_is_the_plain_cell_set_or_varied(tmp_path, capsys):
    """--set env.orca.time_horizon=5 (the paper's) made cells of their own, whose episodes a sweep into a
    Table II folder ran again, where --vary's 5 was Table II's cell."""
    out = ["--out", str(tmp_path / "sw")]
    plain = _plan(capsys, "--experiment", "table2", *out)
    assert _plan(capsys, "--experiment", "table2", "--set", "env.orca.time_horizon=5", *out) == plain
    assert _plan(capsys, "--experiment", "table2", "--set", "env.time_limit=40", *out) == plain
    varied = _plan(capsys, "--experiment", "table2", "--vary", "env.orca.time_horizon=2,5", *out)
    assert varied["CMPC orca.time_horizon=5.0"] == plain["CMPC"]
    other = _plan(capsys, "--experiment", "table2", "--set", "env.orca.time_horizon=2", *out)
    assert other["CMPC"] == varied["CMPC orca.time_horizon=2.0"] != plain["CMPC"]
