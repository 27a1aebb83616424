"""An [mpc] value one controller reads and another does not (DMPC's update rule, CMPC's xi, the coupled NLP's
mode): a sweep gave CMPC a column per value of DMPC's update rule, the same episodes run again under new cell
keys, and `simulate --controller cmpc --set mpc.dmpc_update=...` ran without a word."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipelines.cli import main
from pipelines.commands.sweep_plan import configured_experiment
from pipelines.config import load
from pipelines.experiments.cells import get_experiment

MANY_ROBOTS = Path(__file__).resolve().parents[2] / "docs" / "examples" / "many_robots.toml"


def test_a_dmpc_setting_varies_dmpc_alone():
    cfg = load(sets=["sweep.experiment=controllers", 'sweep.vary="mpc.dmpc_update=jacobi,gauss_seidel"'])
    labels = [label for label, _ in configured_experiment(cfg).methods]
    assert labels == ["cmpc", "dmpc dmpc_update=jacobi", "dmpc dmpc_update=gauss_seidel", "orca", "straight"]


def test_a_set_dmpc_setting_leaves_the_cmpc_cells_alone():
    experiment = configured_experiment(load(sets=["sweep.experiment=table2", "mpc.dmpc_update=gauss_seidel"]))
    methods, table2 = dict(experiment.methods), dict(get_experiment("table2").methods)
    assert methods["CMPC"] == table2["CMPC"]  # its cell key, its records: the sweep's without --set
    assert dict(methods["DMPC"].mpc_overrides) == {"dmpc_update": "gauss_seidel"}
    # ... and CMPC's threshold leaves DMPC alone
    experiment = configured_experiment(load(sets=["sweep.experiment=table2", "mpc.xi=0.01"]))
    assert dict(experiment.methods)["DMPC"] == table2["DMPC"]


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            ["--experiment", "table3", "--set", "mpc.epsilon=0.01"],
            "--set mpc.epsilon: the methods of experiment 'table3' are centralized (CMPC), and epsilon is",
        ),
        (
            ["--experiment", "table3", "--vary", "mpc.dmpc_stop=regret,no_improvement"],
            "--vary: the methods of experiment 'table3' are centralized (CMPC), and dmpc_stop is DMPC's",
        ),
        (
            ["--experiment", "table2", "--set", "mpc.coupled_mode=exact"],
            "the methods of experiment 'table2' couple by ibr, and coupled_mode is the coupled NLP's",
        ),
    ],
)
def test_a_sweep_setting_no_method_reads_is_one_line(tmp_path, capsys, options, message):
    assert main(["sweep", *options, "--out", str(tmp_path / "s"), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            ["--controller", "cmpc", "--set", "mpc.dmpc_update=gauss_seidel"],
            "--set mpc.dmpc_update gauss_seidel changes nothing here, where the runs are centralized (CMPC)",
        ),
        (
            ["--controller", "dmpc", "--set", "mpc.xi=0.01"],
            "where the runs are distributed (DMPC), and xi is CMPC's",
        ),
        (
            ["--controller", "cmpc", "--no-flocking", "--set", "mpc.d_flock=1.5"],
            "where the runs plan without the flocking term (NF), which d_flock shapes",
        ),
        (
            ["--controller", "dmpc", "--set", "mpc.dmpc_relaxation=0.3"],
            'dmpc_update = "jacobi", and dmpc_relaxation is read under dmpc_update = "relaxed" only',
        ),
        (
            ["--controller", "cmpc", "--set", "mpc.multi_start=false", "--set", "mpc.restart_penalty=3"],
            "plan with multi_start = false, and restart_penalty is read under multi_start = true only",
        ),
        (
            ["--controller", "cmpc", "--set", "mpc.guidance_clearance=penalty"],
            'guidance = "none", and guidance_clearance is read under guidance = "standing" only',
        ),
    ],
)
def test_simulate_refuses_a_typed_setting_its_controller_does_not_read(capsys, options, message):
    assert main(["simulate", *options, "--episodes", "1"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_a_config_file_shared_by_both_controllers_still_serves_cmpc(capsys):
    """many_robots.toml states DMPC's update rule beside CMPC's settings: a file is not refused for it."""
    from pipelines.cli import build_parser
    from pipelines.commands.simulate import resolve_run

    args = build_parser().parse_args(
        ["--config", str(MANY_ROBOTS), "simulate", "--controller", "cmpc", "--episodes", "1"]
    )
    assert resolve_run(args).config.mpc.dmpc_update == "gauss_seidel"


@pytest.mark.parametrize(
    ("item", "message"),
    [
        (
            "simulate.seed=7",
            "--set simulate.seed: 7: [simulate] seed applies to simulate only; a sweep's are --seed",
        ),
        (
            "simulate.episodes=5",
            "[simulate] episodes applies to simulate only; a sweep's are --episodes-per-cell",
        ),
    ],
)
def test_a_sweep_refuses_a_simulate_setting_it_has_its_own_of(tmp_path, capsys, item, message):
    """`sweep --set simulate.seed=7` ran seed 0 and `--set simulate.episodes=5` a thousand a cell, without a
    word; [simulate] sensor_range still puts every method behind a sensor."""
    out = str(tmp_path / "s")
    assert main(["sweep", "--experiment", "table2", "--set", item, "--out", out, "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert (
        main(
            ["sweep", "--experiment", "table2", "--set", "simulate.sensor_range=3", "--out", out, "--dry-run"]
        )
        == 0
    )


def test_a_setting_read_under_another_value_varies_only_where_it_is_read():
    """dmpc_relaxation is the relaxed update's alone: `--vary mpc.dmpc_relaxation=0.3,0.7` under Jacobi ran
    DMPC's episodes twice under two cell keys, and a --set of it gave the Jacobi column a key of its own."""
    cfg = load(sets=["sweep.experiment=table2", 'sweep.vary="mpc.dmpc_relaxation=0.3,0.7"'])
    with pytest.raises(Exception, match='dmpc_relaxation is read under dmpc_update = "relaxed" only'):
        configured_experiment(cfg)
    sets = ["sweep.experiment=table2", "mpc.dmpc_update=relaxed", 'sweep.vary="mpc.dmpc_relaxation=0.3,0.7"']
    labels = [label for label, _ in configured_experiment(load(sets=sets)).methods]
    assert labels == ["CMPC", "DMPC dmpc_relaxation=0.3", "DMPC dmpc_relaxation=0.7"]
    sets = ["sweep.experiment=table2", "mpc.dmpc_relaxation=0.3"]
    sets.append('sweep.vary="mpc.dmpc_update=jacobi,relaxed"')
    methods = dict(configured_experiment(load(sets=sets)).methods)
    assert methods["DMPC dmpc_update=jacobi"] == dict(get_experiment("table2").methods)["DMPC"]
    assert dict(methods["DMPC dmpc_update=relaxed"].mpc_overrides)["dmpc_relaxation"] == 0.3


def test_a_files_value_read_under_another_value_keeps_its_cell_keys(tmp_path):
    """A file may set dmpc_relaxation under Jacobi (it serves other runs too): taken, and judged by the
    controller alone, so a folder swept with that file before keeps its cells."""
    path = tmp_path / "run.toml"
    path.write_text("[mpc]\ndmpc_relaxation = 0.3\n", encoding="utf-8")
    experiment = configured_experiment(load(str(path), sets=["sweep.experiment=table2"]))
    assert dict(dict(experiment.methods)["DMPC"].mpc_overrides) == {"dmpc_relaxation": 0.3}


def test_compare_reads_past_a_setting_read_under_another_value():
    from pipelines.loop.unread import record_unread

    def record(update: str) -> dict:
        return {"controller": "dmpc", "config": {"coupling": "ibr", "mpc": {"dmpc_update": update}}}

    assert {"dmpc_relaxation", "restart_penalty", "guidance_clearance"} <= record_unread(
        {"controller": "dmpc", "config": {"mpc": {"multi_start": False}}}
    ) | record_unread(record("jacobi"))
    assert "dmpc_relaxation" not in record_unread(record("relaxed"))
    assert "dmpc_order" not in record_unread(record("gauss_seidel"))
    assert "restart_penalty" not in record_unread(record("relaxed"))  # Table I's multi_start = true
