"""`crowdmpc calibrate --sensor-range M`: closed-loop margins made with the robots behind a sensor, as a robot
that sees M m meets people (docs/replayed_crowds.md, "Behind a sensor"), the range recorded in the block."""

import json
import math

import numpy as np
import pytest

from pipelines.cli import main
from pipelines.errors import PipelineError
from pipelines.experiments.calibrate import ClosedLoopPlan, closed_loop_errors
from predictors.calibration_store import read_calibrations

CALIBRATE = ["calibrate", "--predictor", "constant_velocity", "--source", "closed-loop", "--no-progress"]


@pytest.fixture(autouse=True)
def _private_zoo(tmp_path, monkeypatch):
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "zoo"))


def test_the_episodes_run_behind_the_sensor_and_only_then_the_details_say_so():
    """The same two episodes: behind a 2 m sensor a person is scored from when a robot comes within 2 m of
    them, predicted from the track since (constant velocity from a padded track of one position predicts
    them to stand); with every human seen, from the start, and the details hold no sensor key (the blocks
    made before the option, unchanged)."""
    full = closed_loop_errors(ClosedLoopPlan("constant_velocity", episodes=2, humans=(5,)), progress=False)
    behind = closed_loop_errors(
        ClosedLoopPlan("constant_velocity", episodes=2, humans=(5,), sensor_range=2.0), progress=False
    )
    assert "sensor_range" not in full.details and behind.details["sensor_range"] == 2.0
    assert behind.errors.shape[1] == full.errors.shape[1] == 4
    assert len(behind.errors) < len(full.errors)  # within 3 m of a robot and seen: within 2 m
    # "new" (track shorter than the class window) is far more common behind the sensor
    assert np.mean(behind.classes == 0) > np.mean(full.classes == 0)


@pytest.mark.parametrize("bad", [0.0, -1.0, math.inf, math.nan, True])
def test_a_range_that_is_no_distance_is_refused(bad):
    with pytest.raises(PipelineError, match="--sensor-range must be a finite number of metres > 0"):
        ClosedLoopPlan("constant_velocity", sensor_range=bad)


def test_calibrate_stores_the_range_and_refuses_it_where_it_changes_nothing(tmp_path, capsys):
    out = tmp_path / "c.json"
    argv = [*CALIBRATE, "--alpha", "0.45", "--episodes", "2", "--humans", "4", "--sensor-range", "2.5"]
    assert main([*argv, "--json", str(out)]) == 0
    (block,) = read_calibrations(tmp_path / "zoo")
    assert block.details["sensor_range"] == 2.5 and block.alpha == 0.45
    assert json.loads(out.read_text())["blocks"][0]["details"]["sensor_range"] == 2.5
    capsys.readouterr()
    real = ["calibrate", "--predictor", "constant_velocity", "--source", "real", "--sensor-range", "3"]
    assert main(real) == 2
    err = capsys.readouterr().err
    assert "--sensor-range is for --source closed-loop" in err and err.count("\n") == 1
    assert main([*CALIBRATE, "--sensor-range", "0", "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert "--sensor-range must be a finite number of metres > 0, got 0.0" in err and "Traceback" not in err


def test_a_record_names_the_sensor_its_margins_were_calibrated_behind():
    import dataclasses

    from pipelines.loop.margins import parse_margins
    from predictors.calibration_store import find_calibration, save_calibration

    shipped = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    save_calibration(dataclasses.replace(shipped, details={**shipped.details, "sensor_range": 3.0}))
    from predictors.registry import checkpoint_sha256

    margins, sha256 = parse_margins("conformal-shortfall:0.1"), checkpoint_sha256("social_lstm_eth")
    recorded = margins.behind(3.0).calibration("social_lstm_eth", sha256) or {}
    assert recorded["sensor_range"] == 3.0 and recorded["profile"] == "paper"
    # seeing every human, the block made so (the shipped one), which was stored beside it
    full_view = margins.calibration("social_lstm_eth", sha256) or {}
    assert "sensor_range" not in full_view and full_view["created"] == shipped.created


def test_a_run_behind_the_sensor_plans_with_its_block_and_one_seeing_everyone_with_the_other(tmp_path):
    """After `calibrate --sensor-range 3` both blocks of alpha 0.1 are in force: simulate behind the 3 m
    sensor records the sensor's block and its margins, and without a sensor the shipped block's, as before."""
    import dataclasses

    from predictors.calibration_store import find_calibration, save_calibration

    shipped = find_calibration("constant_velocity", "closed-loop", 0.1)
    wider = tuple(q + 0.25 for q in shipped.quantiles)
    save_calibration(
        dataclasses.replace(shipped, quantiles=wider, details={**shipped.details, "sensor_range": 3.0})
    )
    argv = ["simulate", "--controller", "cmpc", "--predictor", "constant_velocity", "--humans", "1"]
    planned = {}
    for sensor in ([], ["--sensor-range", "3"]):
        out = tmp_path / f"run{len(sensor)}.json"
        assert main([*argv, "--margins", "conformal:0.1", *sensor, "--no-progress", "--json", str(out)]) == 0
        (episode,) = json.loads(out.read_text())["episodes"]
        margins = episode["config"]["margins"]
        made = margins["calibration"]
        planned[bool(sensor)] = (margins["margins_m"], made.get("sensor_range"), made.get("sensor_tracks"))
    assert planned[False] == (list(shipped.quantiles), None, None)
    assert planned[True] == (list(wider), 3.0, True)


def test_a_sensor_block_without_class_margins_is_not_stored_where_runs_behind_it_plan_with_them(capsys):
    """Behind a sensor not calibrated for yet, runs plan with the shipped block of every human in view, which
    has margins per motion class: a short trial behind the sensor (too few samples in a class) would make
    conformal-motion refuse there, so it is not stored, as it is not over a block of its own key."""
    from predictors.calibration_store import find_calibration

    argv = [*CALIBRATE, "--alpha", "0.1", "--episodes", "2", "--humans", "4", "--sensor-range", "2.5"]
    assert find_calibration("constant_velocity", "closed-loop", 0.1, sensor_range=2.5).classes is not None
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "not stored: the new closed-loop block of constant_velocity at alpha 0.1 has no margins" in err
    assert not any(b.sensor_range for b in read_calibrations())  # nothing stored: the shipped blocks alone


def test_no_sensor_tracks_calibrates_behind_a_tracker_that_reports_none_and_needs_a_range(tmp_path, capsys):
    """The controller is given no track lengths (its classes read the padded tracks as a long stay), the
    block records it, and its key stands beside the tracked one's; refused without a range or for real
    scenes, naming the option."""
    argv = [*CALIBRATE, "--alpha", "0.45", "--episodes", "2", "--humans", "4", "--sensor-range", "2.5"]
    assert main(argv) == 0
    assert main([*argv, "--no-sensor-tracks"]) == 0
    blocks = {b.key()[3:]: b for b in read_calibrations(tmp_path / "zoo")}
    assert set(blocks) == {(2.5, False), (2.5, True)}
    assert (
        blocks[2.5, False].details["sensor_tracks"] is False
        and "sensor_tracks" not in blocks[2.5, True].details
    )
    capsys.readouterr()
    assert main([*CALIBRATE, "--no-sensor-tracks", "--dry-run"]) == 2
    assert "--no-sensor-tracks is a sensor's: give --sensor-range M too" in capsys.readouterr().err
    real = ["calibrate", "--predictor", "constant_velocity", "--source", "real", "--no-sensor-tracks"]
    assert main(real) == 2
    assert "--no-sensor-tracks is for --source closed-loop" in capsys.readouterr().err


def test_a_rerun_of_a_calibrate_beyond_the_range_bound_added_since_names_the_blocks_it_made(
    tmp_path, capsys, monkeypatch
):
    """A calibrate behind a 2000 m sensor before crowdsim.world.SENSOR_RANGE's 1000 m, run again (or its
    dry run), was refused in the bound's words alone, as if no block of that sensor were stored: the
    refusal names the file holding them, which stay as they were. Another range's refusal is as before."""
    import crowdsim.world

    argv = [*CALIBRATE, "--alpha", "0.45", "--episodes", "2", "--humans", "4", "--sensor-range", "2000"]
    with monkeypatch.context() as before:
        before.setattr(crowdsim.world, "SENSOR_RANGE", (1e-6, math.inf))
        assert main(argv) == 0
    stored = tmp_path / "zoo" / "calibrations.json"
    held = stored.read_text()
    bound = "crowdmpc calibrate: error: --sensor-range: the sensor range must be at most 1000 m, got"
    for extra in ([], ["--dry-run"]):
        capsys.readouterr()
        assert main([*argv, *extra]) == 2
        assert capsys.readouterr().err == (
            f"{bound} 2000.0; {stored} holds constant_velocity's closed-loop margins behind a 2000 m sensor "
            "(alpha 0.45), made before that bound: they stay, as `crowdmpc zoo calibrations` lists them\n"
        )
    assert main([*argv[:-1], "3000"]) == 2
    assert capsys.readouterr().err == f"{bound} 3000.0\n"
    assert stored.read_text() == held
