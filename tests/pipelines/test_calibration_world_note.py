"""The note on closed-loop margins calibrated under other conventions than the run's (simulate, sweep): one
block is stored per predictor, alpha and sensor range, and a run under another profile or visibility
planned with it without a word about its coverage there."""

import dataclasses

import pytest

from pipelines.cli import main
from pipelines.commands.calibration_notes import calibration_world_note, sensor_margins_note
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.margins import parse_margins
from predictors.calibration_store import find_calibration, save_calibration


def _spec(margins: str, controller: str = "cmpc") -> ControllerSpec:
    return ControllerSpec(controller, "social_lstm_eth", margins=parse_margins(margins))


@pytest.fixture(autouse=True)
def _private_zoo(tmp_path, monkeypatch):
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "zoo"))


def test_the_shipped_calibration_was_measured_under_the_paper_profile_with_visible_robots():
    details = find_calibration("social_lstm_eth", "closed-loop", 0.1).details
    assert (details["profile"], details["visibility"]) == ("paper", "visible")


@pytest.mark.parametrize(
    ("spec", "profile", "visibility"),
    [
        (_spec("conformal:0.1"), "paper", "visible"),  # its own conventions
        (_spec("conformal-motion:0.1", "dmpc"), "paper", "visible"),
        (_spec("none"), "v1", "invisible"),  # no margins
        (_spec("fixed:0.1,0.1,0.1,0.1,0.1,0.1,0.1,0.1"), "v1", "visible"),
        (_spec("conformal:0.1:real"), "v1", "visible"),  # real data: no conventions
        (_spec("conformal:0.3"), "v1", "visible"),  # no such block: refused where margins resolve
        (ControllerSpec("orca", margins=parse_margins("conformal:0.1")), "v1", "visible"),
    ],
)
def test_no_note_where_it_does_not_apply(spec, profile, visibility):
    assert calibration_world_note(spec, profile, visibility) is None


def test_the_note_names_both_conventions_and_the_command_that_measures_the_runs():
    """The command makes the block again under the run's conventions: its own horizon, episodes, seed,
    controller, crowds and scoring range, not calibrate's defaults."""
    assert calibration_world_note(_spec("conformal-shortfall:0.1"), "v1", "invisible") == (
        "note: the closed-loop margins of 'social_lstm_eth' at alpha=0.1 were calibrated under profile paper "
        "with robots visible, this run is v1 with robots invisible: their coverage here is not measured "
        "(crowdmpc calibrate --predictor social_lstm_eth --source closed-loop --alpha 0.1 --horizon 4 "
        "--episodes 200 --seed 1000000 --controller cmpc --humans 5,6,7,8,9 --near 3 --profile v1 "
        "--visibility invisible measures it, replacing that block for every run; CROWDMPC_ZOO=DIR keeps it "
        "apart)"
    )


def test_the_command_carries_a_users_block_of_its_own_settings():
    shipped = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    details = shipped.details | {"controller": "dmpc", "humans": [7], "episodes": 40, "near": None}
    save_calibration(dataclasses.replace(shipped, details=details))
    note = calibration_world_note(_spec("conformal:0.1"), "v1", "visible") or ""
    assert "--episodes 40 --seed 1000000 --controller dmpc --humans 7 --near inf --profile v1" in note


def test_a_users_block_of_other_conventions_is_noted_under_the_paper_profile(capsys):
    shipped = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    v1 = dataclasses.replace(shipped, details={**shipped.details, "profile": "v1", "visibility": "invisible"})
    save_calibration(v1)
    assert "calibrated under profile v1 with robots invisible, this run is paper with robots visible" in (
        calibration_world_note(_spec("conformal:0.1"), "paper", "visible") or ""
    )
    args = ["simulate", "--controller", "cmpc", "--predictor", "social_lstm_eth"]
    assert main([*args, "--margins", "conformal:0.1", "--humans", "1", "--no-progress"]) == 0
    assert "note: the closed-loop margins of 'social_lstm_eth'" in capsys.readouterr().err


def test_a_sweep_says_it_once_naming_the_methods(tmp_path, capsys):
    argv = ["sweep", "--experiment", "conventions", "--dry-run", "--out", str(tmp_path)]
    assert main(argv) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "were calibrated under" in line]
    assert [note.split(":")[0:2] for note in notes] == [
        ["note", " method 'v1/visible/cp0.1'"],
        ["note", " method 'v1/invisible/cp0.1'"],
        ["note", " method 'paper/invisible/cp0.1'"],
    ]


@pytest.mark.parametrize(
    ("spec", "sensor_range"),
    [
        (_spec("conformal:0.1"), None),  # every human seen: the calibration's own view
        (_spec("none"), 3.0),
        (_spec("fixed:0.1,0.1,0.1,0.1,0.1,0.1,0.1,0.1"), 3.0),  # metres chosen, not calibrated
        (ControllerSpec("orca", margins=parse_margins("conformal:0.1")), 3.0),
    ],
)
def test_no_sensor_note_where_it_does_not_apply(spec, sensor_range):
    assert sensor_margins_note(spec, sensor_range) is None


def test_behind_a_sensor_calibrated_margins_are_noted_with_what_was_measured_there(tmp_path, capsys):
    """Every calibration was made with every person in view: behind a sensor, people just come into view are
    predicted from short tracks, and the margins covered less (docs/replayed_crowds.md, "Behind a sensor")."""
    assert sensor_margins_note(_spec("conformal-shortfall:0.05", "dmpc"), 2.5) == (
        "note: the closed-loop margins of 'social_lstm_eth' at alpha=0.05 were calibrated with every person "
        "in view; behind a sensor of 2.5 m a person just come into view is predicted from a short track, and "
        'they cover less than calibrated (docs/replayed_crowds.md, "Behind a sensor": at 3 m, alpha=0.1 '
        "covered 0.83-0.87 among ORCA's humans, where 0.90 was calibrated); crowdmpc calibrate --predictor "
        "social_lstm_eth --source closed-loop --alpha 0.05 --horizon 4 --episodes 200 --seed 1000000 "
        "--controller cmpc --humans 5,6,7,8,9 --near 3 --sensor-range 2.5 calibrates behind this run's "
        "sensor, stored beside that block"
    )
    real = sensor_margins_note(_spec("conformal:0.1:real"), 3) or ""
    assert "among BIWI's people" in real and "crowdmpc calibrate" not in real  # no real one behind a sensor
    args = ["simulate", "--controller", "cmpc", "--predictor", "social_lstm_eth", "--humans", "1"]
    assert main([*args, "--margins", "conformal:0.1", "--sensor-range", "3", "--no-progress"]) == 0
    assert capsys.readouterr().err.count("were calibrated with every person in view") == 1
    sweep = [
        "sweep",
        "--experiment",
        "sensing",
        "--margins",
        "conformal:0.1",
        "--dry-run",
        "--out",
        str(tmp_path),
    ]
    assert main(sweep) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "with every person in view" in line]
    assert [note.split(":")[1] for note in notes] == [  # the untracked column's command says so
        " method '4 m'",
        " method '3 m'",
        " method '2 m'",
        " method '3 m untracked'",
    ]
    command = (
        "--sensor-range 3 --no-sensor-tracks calibrates behind this run's sensor, stored beside that block"
    )
    assert notes[-1].endswith(command)


def test_margins_calibrated_behind_a_sensor_are_noted_where_the_run_sees_otherwise():
    """`calibrate --sensor-range 3` records the range in its block: a run behind the same sensor plans with
    it silently; one that sees everyone, or behind another range, with no block of its own view, is told,
    with the command for its own. (Alpha 0.15: the shipped zoo has no block of every human in view there.)"""
    shipped = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    behind = {**shipped.details, "sensor_range": 3.0}
    save_calibration(dataclasses.replace(shipped, alpha=0.15, details=behind))
    spec = _spec("conformal-motion:0.15")
    assert sensor_margins_note(spec, 3.0) is None
    command = (
        "crowdmpc calibrate --predictor social_lstm_eth --source closed-loop --alpha 0.15 --horizon 4 "
        "--episodes 200 --seed 1000000 --controller cmpc --humans 5,6,7,8,9 --near 3"
    )
    assert sensor_margins_note(spec, None) == (
        "note: the closed-loop margins of 'social_lstm_eth' at alpha=0.15 were calibrated behind a sensor of "
        "3 m, this run's robots see every human: made for people just come into view, they are wider than it "
        f'needs (docs/replayed_crowds.md, "Behind a sensor"); {command} calibrates with every person in '
        "view, stored beside that block"
    )
    assert sensor_margins_note(spec, 4.0) == (
        "note: the closed-loop margins of 'social_lstm_eth' at alpha=0.15 were calibrated behind a sensor of "
        f"3 m, this run's is 4 m: their coverage here is not measured; {command} --sensor-range 4 calibrates "
        "behind this run's sensor, stored beside that block"
    )
    # the conventions note's command makes the same block under the run's conventions: behind its sensor
    world = calibration_world_note(spec, "v1", "visible", sensor_range=3.0) or ""
    assert "--near 3 --sensor-range 3 --profile v1 --visibility visible measures it" in world


def test_a_block_made_behind_the_runs_sensor_stands_beside_the_one_of_every_human_in_view():
    """Both blocks of alpha 0.1 in force: a run behind the 3 m sensor plans with its block, silently; a run
    that sees everyone, or is behind a 4 m sensor, with the shipped one (noted behind the 4 m sensor)."""
    shipped = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    save_calibration(dataclasses.replace(shipped, details={**shipped.details, "sensor_range": 3.0}))
    spec = _spec("conformal-motion:0.1")
    assert sensor_margins_note(spec, 3.0) is None and sensor_margins_note(spec, None) is None
    assert "were calibrated with every person in view" in (sensor_margins_note(spec, 4.0) or "")
    v1 = calibration_world_note(spec, "v1", "visible", sensor_range=3.0) or ""
    assert "--sensor-range 3 --profile v1" in v1
    assert "--sensor-range" not in (calibration_world_note(spec, "v1", "visible") or "-")


def test_a_tracker_reporting_track_lengths_the_other_way_is_noted_with_the_command_for_its_own():
    shipped = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    behind = {**shipped.details, "sensor_range": 3.0}
    save_calibration(dataclasses.replace(shipped, alpha=0.15, details=behind))
    spec = _spec("conformal-motion:0.15")
    assert sensor_margins_note(spec, 3.0, True) is None
    note = sensor_margins_note(spec, 3.0, False) or ""
    assert note.startswith(
        "note: the closed-loop margins of 'social_lstm_eth' at alpha=0.15 were calibrated behind a sensor of "
        "3 m with the tracker's track lengths, this run's controller plans without them: it classes the "
        "people who just came into view otherwise, and the coverage here is not measured; crowdmpc calibrate"
    )
    assert note.endswith(
        "--near 3 --sensor-range 3 --no-sensor-tracks calibrates behind this run's sensor, stored beside "
        "that block"
    )
    untracked = {**behind, "sensor_tracks": False}
    save_calibration(dataclasses.replace(shipped, alpha=0.15, details=untracked))
    assert sensor_margins_note(spec, 3.0, False) is None
    world = calibration_world_note(spec, "v1", "visible", sensor_range=3.0, sensor_tracks=False) or ""
    assert "--sensor-range 3 --no-sensor-tracks --profile v1 --visibility visible measures it" in world


def test_margins_planned_with_in_another_world_or_crowd_motion_say_so():
    """calibrate reads no config: its blocks are of Table I's world and the profile's ORCA humans, and a
    run of slower people (world.v_pref 0.5), larger robots or a shorter ORCA horizon planned with them
    silently."""
    from pipelines.commands.calibration_notes import calibration_physics_note, changed_physics
    from pipelines.config import load

    cfg = load(sets=["world.v_pref=0.5", "env.time_limit=60", "env.orca.time_horizon=2", "world.radius=0.3"])
    # the time limit moves no one; a value set to its default (radius 0.3) changes nothing
    assert changed_physics(cfg) == ["world.v_pref 0.5", "env.orca.time_horizon 2.0"]
    note = calibration_physics_note(_spec("conformal:0.1"), ["world.v_pref 0.5"]) or ""
    assert note.startswith(
        "note: the closed-loop margins of 'social_lstm_eth' at alpha=0.1 were calibrated in "
    )
    assert note.endswith("this run sets world.v_pref 0.5: their coverage here is not measured")
    assert calibration_physics_note(_spec("conformal:0.1"), []) is None  # Table I's world
    assert calibration_physics_note(_spec("conformal:0.1:real"), ["world.v_pref 0.5"]) is None  # real people
    assert calibration_physics_note(_spec("none"), ["world.v_pref 0.5"]) is None


def test_another_team_or_crowd_size_than_calibrated_is_noted():
    """The shipped block was measured with 3 robots among 5-9 humans; a run of 5 robots among 15 planned
    with it without a word (the conventions, controller and world were noted, not the team)."""
    from pipelines.commands.calibration_notes import calibration_team_note
    from pipelines.commands.sweep_checks import method_notes
    from pipelines.experiments.cells import get_experiment

    spec = _spec("conformal:0.1")
    assert calibration_team_note(spec, [5, 7, 9], 3) is None  # the calibration's own team and sizes
    assert calibration_team_note(_spec("none"), [15], 5) is None  # no calibrated margins
    assert calibration_team_note(_spec("conformal:0.1:real"), [15], 5) is None  # real people: no team
    note = calibration_team_note(spec, [4, 7, 15], 5)
    assert note is not None and note.endswith(
        "were calibrated with 3 robots among 5-9 humans (calibrate's episodes; --humans sets their crowds), "
        "this run has 5 robots and 4, 15 humans: their coverage here is not measured"
    )
    table2 = get_experiment("table2").with_margins(parse_margins("conformal:0.1"))
    notes = [n for n in method_notes(table2.cells((5, 10))) if "calibrated with 3 robots" in n]
    assert notes == [f"note: methods 'CMPC', 'DMPC': {calibration_team_note(spec, [10], 3)[6:]}"]


def test_a_team_of_one_robot_or_a_crowd_of_one_human_is_counted_in_the_singular():
    """simulate --robots 1 --humans 2 with conformal margins noted "this run has 1 robots and 2 humans"."""
    from pipelines.commands.calibration_notes import calibration_team_note

    spec = _spec("conformal:0.1")
    one_robot = calibration_team_note(spec, [2], 1) or ""
    assert one_robot.endswith("this run has 1 robot and 2 humans: their coverage here is not measured")
    one_human = calibration_team_note(spec, [1], 3) or ""
    assert one_human.endswith("this run has 1 human: their coverage here is not measured")
    several = calibration_team_note(spec, [1, 2], 3) or ""  # sizes listed: "humans" as before
    assert several.endswith("this run has 1, 2 humans: their coverage here is not measured")
