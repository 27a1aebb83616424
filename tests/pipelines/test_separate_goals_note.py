"""The note on robots trading places whom every pair flocking holds together (simulate, sweep): said once,
before the first episode, in the command line's words. A sweep's workers each printed the controller's
``FlockWarning`` (two identical lines from two workers, the library's ``mpc_overrides=...`` among them)."""

from __future__ import annotations

import math

import pytest

from pipelines.cli import main
from pipelines.commands.team_notes import flock_note, separate_goals_note
from pipelines.loop.spec import ControllerSpec


def test_the_antipodal_circle_of_four_by_hand():
    """Robots on the 3.5 m circle at -90, 0, 90 and 180 degrees, each bound for the opposite point: robots 0
    and 1's goals (0, 3.5) and (-3.5, 0) lie 3.5 sqrt 2 = 4.95 m apart, and every pair's offset turns round
    (2 x 4.95 m or more of change, beyond 2 d_flock = 2.4 m): no pair keeps its shape, so the team's own
    goal distance is d_flock, 1.2 m, and the range is 1.2 + 0.5 = 1.70 m (below halfway to 4.95 m)."""
    assert f"{3.5 * math.sqrt(2):.1f}" == "4.9"
    assert separate_goals_note(ControllerSpec("dmpc"), 4, "antipodal") == (
        "note: robots 0 and 1 are bound for goals 4.9 m apart by separate ways, and Eq. 15 pulls every pair "
        "of robots towards d_flock 1.2 m, which can hold them together until the time limit: --set "
        "mpc.flock_range=1.70 ([mpc] flock_range) flocks only the pairs whose goals lie within 1.70 m "
        '(docs/extending.md, "Robots bound for separate places")'
    )


@pytest.mark.parametrize(
    ("spec", "robots", "formation"),
    [
        (ControllerSpec("cmpc"), 12, "row"),  # a team keeping its shape
        (ControllerSpec("cmpc"), 6, "wedge"),
        (ControllerSpec("cmpc", mpc_overrides=(("flock_range", 2.0),)), 4, "antipodal"),
        (ControllerSpec("cmpc", flocking=False), 4, "antipodal"),
        (ControllerSpec("orca"), 4, "antipodal"),
        (ControllerSpec("cmpc"), 1, "antipodal"),
    ],
)
def test_no_note_where_no_pair_parts(spec, robots, formation):
    assert separate_goals_note(spec, robots, formation) is None


def test_the_flocking_weight_note_counts_the_partners_a_range_leaves():
    """With flock_range a robot flocks with the teammates whose goals lie within it. On the antipodal circle
    of 12 a robot's neighbours' goals lie 7 sin(pi / 12) = 1.81 m off, the next 3.5 m: two partners within
    2 m, as many as in the paper's team of 3, so no note; the row of 12 at 1 m: two within 1.5 m (no note),
    four within 2.5 m (the note)."""
    assert 1.81 < 7 * math.sin(math.pi / 12) < 2.0 < 7 * math.sin(2 * math.pi / 12)
    ranged = ControllerSpec("cmpc", mpc_overrides=(("flock_range", 2.0),))
    assert flock_note(ranged, 12, "antipodal") is None
    assert flock_note(ControllerSpec("cmpc"), 12, "antipodal") is not None  # every pair: 11 partners
    assert flock_note(ControllerSpec("cmpc", mpc_overrides=(("flock_range", 1.5),)), 12, "row") is None
    wide = flock_note(ControllerSpec("cmpc", mpc_overrides=(("flock_range", 2.5),)), 12, "row")
    assert wide is not None and wide.startswith("note: 12 robots under the paper's per-pair flocking weight")


ANTIPODAL = ["--set", "env.formation=antipodal", "--set", "env.time_limit=2", "--no-progress"]


def test_simulate_says_it_once_in_its_own_words(capsys):
    argv = ["simulate", "--controller", "dmpc", "--robots", "3", "--humans", "1", "--episodes", "2"]
    assert main([*argv, *ANTIPODAL]) == 0
    err = capsys.readouterr().err
    assert err.count("are bound for goals") == 1 and "--set mpc.flock_range=1.70" in err
    assert "mpc_overrides" not in err and "FlockWarning" not in err
    assert main([*argv, *ANTIPODAL, "--set", "mpc.flock_range=1.7"]) == 0
    assert "are bound for goals" not in capsys.readouterr().err


def test_a_sweep_says_it_once_whatever_its_workers(tmp_path, capsys):
    argv = ["sweep", "--experiment", "controllers", "--controllers", "cmpc,dmpc", "--robots", "3"]
    argv += ["--humans", "1", "--episodes-per-cell", "2", "--workers", "2", "--out", str(tmp_path / "sw")]
    assert main([*argv, *ANTIPODAL]) == 0
    err = capsys.readouterr().err
    assert err.count("are bound for goals") == 1, err
    assert "note: methods 'cmpc', 'dmpc': robots 0 and 1 are bound for goals 6.1 m apart" in err
    assert "mpc_overrides" not in err
