"""``crowdmpc simulate``'s note for a flock larger than the paper's 3 under the per-pair flocking weight."""

import pytest

from pipelines.cli import main
from pipelines.commands.team_notes import flock_note
from pipelines.loop.spec import ControllerSpec

PER_ROBOT = (("flocking_weight", "per_robot"),)


def test_the_note_names_the_weight_and_the_way_out():
    note = flock_note(ControllerSpec("dmpc"), 6)
    assert note is not None and note.startswith("note: 6 robots under the paper's per-pair flocking weight")
    assert "--set mpc.flocking_weight=per_robot" in note and "docs/examples/many_robots.toml" in note


@pytest.mark.parametrize(
    ("spec", "robots"),
    [
        (ControllerSpec("cmpc"), 3),  # the paper's team: nothing to say
        (ControllerSpec("cmpc", mpc_overrides=PER_ROBOT), 12),
        (ControllerSpec("cmpc", flocking=False), 12),  # Table III's "NF"
        (ControllerSpec("cmpc", mpc_overrides=(("w_floc", 0.0),)), 12),
        (ControllerSpec("orca"), 12),  # no flocking term at all
    ],
)
def test_no_note_where_it_does_not_apply(spec, robots):
    assert flock_note(spec, robots) is None


def test_simulate_prints_it_on_stderr_before_the_table(capsys):
    argv = ["simulate", "--controller", "cmpc", "--robots", "4", "--humans", "1", "--episodes", "1"]
    assert main([*argv, "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert "note: 4 robots under the paper's per-pair flocking weight" in err
    assert "note:" not in out and out.startswith("controller cmpc")
