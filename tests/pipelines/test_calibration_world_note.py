"""The note on closed-loop margins calibrated under other conventions than the run's (simulate, sweep): one
block is stored per predictor and alpha, and a run under another profile or visibility planned with it
without a word about its coverage there."""

import dataclasses

import pytest

from pipelines.cli import main
from pipelines.commands.simulate_checks import calibration_world_note
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
        "--visibility invisible measures it, replacing that block)"
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
