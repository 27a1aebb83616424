"""Sweeps of robots that see a few metres: ``World``'s sensor range in the cell keys and records, the sensing
experiment, ``sweep --sensor-range M [--no-sensor-tracks]``, and a sensed sweep episode being simulate's."""

import csv
import dataclasses
import json
import math

import pytest

from pipelines.cli import main
from pipelines.commands.sweep_jit import jit_pays
from pipelines.errors import PipelineError
from pipelines.experiments.cells import get_experiment
from pipelines.experiments.safety_report import world_note
from pipelines.experiments.tasks import Cell, EpisodeTask, World
from pipelines.experiments.worker import EpisodeWorker
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.episode import run_episodes


def test_a_world_that_sees_every_human_keeps_the_key_of_the_sweeps_before_sensing():
    """Sweeps written before sensing resume into the same cells: their keys are unchanged."""
    (cmpc, dmpc) = get_experiment("table2").cells(humans=(7,))
    assert cmpc.key == "cmpc-social_lstm_eth-F-ibr-m=none-paper-visible-h7-r3"
    assert World().sensing_label == "every human"
    sensed = dataclasses.replace(dmpc, world=World().sensing(2.5, sensor_tracks=False))
    assert sensed.key == "dmpc-social_lstm_eth-F-ibr-m=none-paper-visible-sensed2.5m-notracks-h7-r3"
    assert sensed.world.sensing_label == "2.5 m untracked"
    assert World().sensing(3).label == "paper-visible-sensed3m"


@pytest.mark.parametrize("value", [0, -1.0, math.nan, math.inf, True, "3"])
def test_a_sensor_range_that_is_no_distance_is_refused(value):
    with pytest.raises(PipelineError, match=r"a sensor range must be a finite number of metres > 0, got"):
        World(sensor_range=value)


def test_track_lengths_need_a_sensor_and_a_boolean():
    with pytest.raises(PipelineError, match="sensor_tracks = false needs a sensor range"):
        World(sensor_tracks=False)
    with pytest.raises(PipelineError, match="sensor_tracks must be true or false, got 'no'"):
        World(sensor_range=3.0, sensor_tracks="no")  # type: ignore[arg-type]


def test_the_sensing_experiment_compares_ranges_on_the_same_crowds():
    experiment = get_experiment("sensing")
    cells = experiment.cells()
    assert [c.method for c in cells] == ["full", "4 m", "3 m", "2 m", "3 m untracked"]
    assert [(c.world.sensor_range, c.world.sensor_tracks) for c in cells] == [
        (None, True),
        (4.0, True),
        (3.0, True),
        (2.0, True),
        (3.0, False),
    ]
    assert {c.spec for c in cells} == {ControllerSpec("cmpc", "social_lstm_eth")}
    with pytest.raises(PipelineError, match="'sensing' compares sensor ranges across its methods"):
        experiment.with_sensing(3.0)
    # the profile and visibility still apply, each column keeping its range
    v1 = experiment.with_world(World("v1", "invisible")).cells()
    assert [(c.world.profile, c.world.sensor_range) for c in v1][:2] == [("v1", None), ("v1", 4.0)]
    assert {c.world.visibility for c in v1} == {"invisible"}


def test_a_sensor_puts_every_method_of_an_experiment_behind_it_and_says_so():
    table2 = get_experiment("table2").with_sensing(3.0)
    assert {c.world for c in table2.cells()} == {World().sensing(3.0)}
    assert table2.title.endswith("; controllers behind a 3 m sensor")
    # the conventions experiment's own worlds keep their profile and visibility
    conventions = get_experiment("conventions").with_sensing(2.0, sensor_tracks=False)
    worlds = {c.world for c in conventions.cells()}
    assert {(w.sensor_range, w.sensor_tracks) for w in worlds} == {(2.0, False)}
    assert {(w.profile, w.visibility) for w in worlds} == {
        (p, v) for p in ("v1", "paper") for v in ("visible", "invisible")
    }
    with pytest.raises(PipelineError, match="fixes each method's profile and visibility"):
        conventions.with_world(World("v1"))


def test_the_table_note_names_the_sensing_only_where_some_column_senses():
    table2 = get_experiment("table2")
    assert world_note(table2.cells())[0] == "Margins: none; profile paper, robots visible to the humans."
    line, worlds = world_note(table2.with_sensing(3.0, sensor_tracks=False).cells())
    assert (line, worlds) == (
        "Margins: none; profile paper, robots visible to the humans, sensor range 3 m untracked.",
        None,
    )
    line, worlds = world_note(get_experiment("sensing").cells())
    assert line == (
        "Margins: none; profile paper, robots visible to the humans, sensing per column "
        "(row 'Margins / profile / visibility / sensing')."
    )
    assert worlds is not None and worlds[:2] == [
        "none / paper / visible / every human",
        "none / paper / visible / 4 m",
    ]


def test_compiling_counts_every_crowd_size_a_sensed_cell_meets():
    """Behind a sensor a CMPC meets 0..n humans, an NLP each: jit_pays counts them (one cold compile
    each), so --jit auto does not compile where the unsensed cell would repay it."""
    from mpc.compile_cache import COMPILE_S, SAVING_PER_EPISODE_S

    full = Cell("CMPC", ControllerSpec("cmpc", "social_lstm_eth"), 7)
    sensed = dataclasses.replace(full, world=World().sensing(3.0))
    # enough episodes to repay one NLP's compile, not eight
    episodes = math.ceil(COMPILE_S["joint"] / SAVING_PER_EPISODE_S["joint"])
    assert jit_pays([full], episodes)
    assert not jit_pays([sensed], episodes)
    assert jit_pays([sensed], 8 * episodes)


def test_a_sensed_sweep_episode_is_simulates_metric_for_metric_and_its_record_says_what_it_saw():
    spec = ControllerSpec("cmpc", "constant_velocity")
    world = World().sensing(2.0)
    cell = Cell("CMPC", spec, 4, world=world)
    outcome = EpisodeWorker().run(EpisodeTask("sensing", cell, 1, "perpendicular", 0))
    assert outcome.error is None
    (alone,) = run_episodes(
        spec, episodes=1, seed=0, scenario="perpendicular", n_humans=4, sensor_range=2.0, progress=False
    )
    record = outcome.record
    assert record is not None
    assert record["metrics"] == alone.metrics.as_dict()
    assert (record["sensor_range"], record["sensor_tracks"]) == (2.0, True)
    assert record["config"]["sensing"] == {"radius_m": 2.0, "report_tracks": True}
    full = EpisodeWorker().run(
        EpisodeTask("sensing", dataclasses.replace(cell, world=World()), 1, "perpendicular", 0)
    )
    assert full.record is not None and (full.record["sensor_range"], full.record["sensor_tracks"]) == (
        None,
        None,
    )
    assert "sensing" not in full.record["config"]


def test_sweep_sensor_range_runs_every_method_behind_the_sensor_and_reports_it(tmp_path, capsys):
    out = tmp_path / "sw"
    # a file's switch: typed, it is refused for ORCA and the straight line, which read no pasts
    # (test_sweep_idle_choices), while a file may serve the controllers that do
    (tmp_path / "run.toml").write_text("[simulate]\nsensor_tracks = false\n")
    args = ["--config", str(tmp_path / "run.toml"), "sweep", "--experiment", "baselines", "--humans", "3"]
    args += ["--episodes-per-cell", "2", "--backend", "inline", "--no-progress", "--sensor-range", "2"]
    assert main([*args, "--out", str(out)]) == 0
    lines = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert len(lines) == 4
    assert {(r["sensor_range"], r["sensor_tracks"]) for r in lines} == {(2.0, False)}
    assert all(r["cell"].endswith("-paper-visible-sensed2m-notracks-h3-r3") for r in lines)
    with open(out / "cells.csv", encoding="utf-8") as f:
        assert {row["sensing"] for row in csv.DictReader(f)} == {"2 m untracked"}
    with open(out / "episodes.csv", encoding="utf-8") as f:
        assert {(row["sensor_range"], row["sensor_tracks"]) for row in csv.DictReader(f)} == {
            ("2.0", "False")
        }
    table = (out / "table.md").read_text()
    assert "controllers behind a 2 m untracked sensor" in table
    assert "sensor range 2 m untracked." in table


@pytest.mark.parametrize(
    "options, message",
    [
        (
            ["--experiment", "sensing", "--sensor-range", "3"],
            "experiment 'sensing' compares sensor ranges across its methods; --sensor-range and "
            "--no-sensor-tracks do not apply",
        ),
        (
            ["--experiment", "table2", "--no-sensor-tracks"],
            "--no-sensor-tracks: track lengths are a sensor's; give --sensor-range M too",
        ),
        (
            ["--experiment", "table2", "--sensor-range", "0"],
            "--sensor-range must be a finite number of metres > 0",
        ),
    ],
)
def test_sweep_refuses_a_sensor_it_cannot_apply(tmp_path, capsys, options, message):
    assert main(["sweep", *options, "--dry-run", "--out", str(tmp_path / "sw")]) != 0
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "sw").exists()


def test_a_config_files_sensor_applies_to_a_sweep_and_its_refusal_names_the_file(tmp_path, capsys):
    config = tmp_path / "run.toml"
    config.write_text("[simulate]\nsensor_range = 4\n")
    args = ["--config", str(config), "sweep", "--humans", "5", "--episodes-per-cell", "2", "--dry-run"]
    assert main([*args, "--experiment", "table2", "--out", str(tmp_path / "a")]) == 0
    assert "-paper-visible-sensed4m-h5-r3" in capsys.readouterr().out
    assert main([*args, "--experiment", "sensing", "--out", str(tmp_path / "b")]) != 0
    err = capsys.readouterr().err
    assert "simulate.sensor_range" in err and "[simulate] sensor_range and sensor_tracks do not apply" in err


def test_each_column_of_the_sensing_experiment_plans_with_the_block_of_its_own_sensor(
    tmp_path, monkeypatch, capsys
):
    """With a block calibrated behind 3 m stored beside the shipped one, the sensing experiment's two 3 m
    columns plan with it and the others with the shipped block; resuming the sweep finds the same margins
    (pipelines.experiments.resume_checks), and a later block of another view changes only its columns'."""
    from predictors.calibration_store import find_calibration, save_calibration

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "zoo"))
    shipped = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    wider = tuple(q + 0.25 for q in shipped.quantiles)
    save_calibration(
        dataclasses.replace(shipped, quantiles=wider, details={**shipped.details, "sensor_range": 3.0})
    )
    out = tmp_path / "sw"
    args = ["sweep", "--experiment", "sensing", "--humans", "1", "--margins", "conformal:0.1"]
    args += ["--backend", "inline", "--no-progress", "--out", str(out), "--episodes-per-cell"]
    assert main([*args, "1"]) == 0
    lines = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    planned = {r["method"]: tuple(r["config"]["margins"]["margins_m"]) for r in lines}
    assert planned == {"full": shipped.quantiles, "4 m": shipped.quantiles, "2 m": shipped.quantiles} | {
        "3 m": wider,
        "3 m untracked": wider,
    }
    assert main([*args, "2"]) == 0  # resumed: the margins each cell plans with agree with its records
    behind_2m = {**shipped.details, "sensor_range": 2.0}
    save_calibration(dataclasses.replace(shipped, quantiles=wider[::-1], details=behind_2m))
    capsys.readouterr()
    assert main([*args, "3"]) == 2  # the 2 m column's margins changed
    err = capsys.readouterr().err
    assert "-sensed2m-h1-r3 planned with margins" in err and "they changed since" in err
