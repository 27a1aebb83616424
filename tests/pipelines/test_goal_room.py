"""The note on a d_min that leaves two robots no room at their goals (simulate, sweep): the MPC keeps every
pair d_min apart, and the row of 3 puts their goals 1.0 m apart, so a d_min study's 1.0 m column timed out
in every episode for a reason no metric names."""

import warnings

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from crowdsim.scenarios import Layout
from mpc.config import MPCConfig
from pipelines.cli import main
from pipelines.commands.team_notes import goal_room_note, radius_note
from pipelines.errors import GoalRoomWarning
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.team_layout import warn_goal_room


def _spec(controller: str = "cmpc", d_min: float | None = None) -> ControllerSpec:
    overrides = () if d_min is None else (("d_min", d_min),)
    return ControllerSpec(controller, "constant_velocity", mpc_overrides=overrides)


@pytest.mark.parametrize(
    "spec, robots, formation",
    [
        (_spec(), 3, "auto"),  # Table I's 0.8 m, goals 1.0 m apart
        (_spec(d_min=0.94), 3, "row"),  # more than 0.05 m below
        (_spec(d_min=1.1), 3, "wedge"),  # the wedge's goals are d_flock = 1.2 m apart
        (_spec("orca"), 3, "row"),  # no MPC
        (_spec(d_min=2.0), 1, "row"),  # no pair
    ],
)
def test_no_note_where_the_goals_leave_room(spec, robots, formation):
    assert goal_room_note(spec, robots, formation) is None


def test_the_note_names_the_distance_the_formation_and_the_spacing_that_gives_room():
    # the row of 4 reached its goals in no episode at 0.98 m (within 0.05 m of its 1.0 m)
    note = goal_room_note(_spec(d_min=0.98), 4, "row")
    assert note is not None and note.startswith(
        "note: the MPC's d_min 0.98 m is not well below the 1 m between two robots' goals (row of 4)"
    )
    # d_min + 0.3 m, up to 5 cm: 1.28 -> 1.3
    assert note.endswith(
        "(measured thresholds: docs/extending.md); [env] robot_spacing = 1.3 (--set env.robot_spacing=1.3) "
        "spaces them 1.3 m apart"
    )
    wedge = goal_room_note(_spec("dmpc", 1.2), 4, "auto")
    assert wedge is not None and "1.2 m between two robots' goals (wedge of 4)" in wedge
    # past d_flock 1.2 by more than 0.25 m, with the flocking distances that let a row of 3 at 1.5 m arrive
    assert wedge.endswith(
        'robot_spacing = 1.5 with [mpc] flock_distance = "goals" (--set env.robot_spacing=1.5 --set '
        "mpc.flock_distance=goals) spaces them 1.5 m apart"
    )
    # spaced so, no note; beyond the widest spacing taken (2.5 m), no hint
    assert goal_room_note(_spec(d_min=1.0), 3, "row", 1.3) is None
    assert goal_room_note(_spec(d_min=2.3), 3, "row").endswith("docs/extending.md)")


def test_goals_further_apart_than_the_flocking_distance_are_named_with_the_way_out():
    """A row spaced 1.5 m timed out in every episode with no humans about (its outer robots parked 0.39 m
    short: Eq. 15 pulls every pair towards d_flock 1.2 m), and nothing said why."""
    note = goal_room_note(_spec(), 3, "row", 1.5)
    assert note is not None and note.startswith(
        "note: the robots' closest goals are 1.5 m apart (row of 3), beyond the MPC's flocking distance "
        "d_flock 1.2 m"
    )
    assert note.endswith(
        "2 of 2 with --set mpc.flock_distance=goals, which gives each pair its goals' distance)"
    )
    assert goal_room_note(_spec(), 3, "row", 1.4) is None  # arrived: within FLOCK_SLACK
    matched = ControllerSpec("cmpc", "constant_velocity", mpc_overrides=(("d_flock", 1.5),))
    assert goal_room_note(matched, 3, "row", 1.5) is None
    assert goal_room_note(ControllerSpec("cmpc", flocking=False), 3, "row", 1.5) is None  # no Eq. 15
    goals = ControllerSpec("cmpc", "constant_velocity", mpc_overrides=(("flock_distance", "goals"),))
    assert goal_room_note(goals, 3, "row", 1.5) is None
    # flock_range: the closest goals (1.5 m) beyond it flock with nobody; within it, they still do
    apart = ControllerSpec("cmpc", "constant_velocity", mpc_overrides=(("flock_range", 1.4),))
    assert goal_room_note(apart, 3, "row", 1.5) is None
    near = ControllerSpec("cmpc", "constant_velocity", mpc_overrides=(("flock_range", 2.0),))
    assert goal_room_note(near, 3, "row", 1.5) == note


def test_simulate_and_sweep_say_it_once(tmp_path, capsys):
    args = ["simulate", "--controller", "cmpc", "--humans", "0", "--episodes", "1", "--no-progress"]
    assert main([*args, "--set", "mpc.d_min=0.9"]) == 0
    assert "note: the MPC's d_min" not in capsys.readouterr().err
    assert main([*args, "--set", "mpc.d_min=1.0"]) == 0
    assert capsys.readouterr().err.count("note: the MPC's d_min 1 m is not well below") == 1
    assert main([*args, "--set", "mpc.d_min=1.0", "--set", "env.robot_spacing=1.3"]) == 0
    assert "note: the MPC's d_min" not in capsys.readouterr().err
    sweep = ["sweep", "--experiment", "table2", "--humans", "5,6", "--episodes-per-cell", "2", "--dry-run"]
    assert main([*sweep, "--vary", "mpc.d_min=0.8,1.0", "--out", str(tmp_path / "sw")]) == 0
    err = capsys.readouterr().err
    # one line naming both methods it applies to
    assert err.count("note: methods 'CMPC d_min=1.0', 'DMPC d_min=1.0': the MPC's d_min 1 m") == 1
    assert err.count("the MPC's d_min") == 1 and "d_min=0.8'" not in err


def test_a_robot_smaller_than_the_mpcs_parking_gets_a_note_naming_the_way_out():
    """[world] radius 0.01 m: the row of 3 timed out in every episode with nobody about (its outer robots
    parked 4 cm off goals they must reach within 1 cm), and nothing said why. The note names the spacing and
    flocking distance that arrived; none for Table I's radius, flocking that leaves the goals' shape alone at
    1.2 m or more, ORCA or one robot."""
    note = radius_note(_spec(), 3, 0.01, "auto", None)
    assert note is not None and note.startswith(
        "note: robots arrive within [world] radius 0.01 m of their goals, and the MPC can hold them a few "
        "centimetres off (row of 3, goals 1 m apart;"
    )
    assert note.endswith("--set env.robot_spacing=1.2 --set mpc.flock_distance=goals arrived within 0.1 mm")
    goals = ControllerSpec("cmpc", mpc_overrides=(("flock_distance", "goals"),))
    assert radius_note(goals, 3, 0.01, "row", 1.2) is None
    assert radius_note(goals, 3, 0.01, "row", 1.1) is not None  # Eq. 12's tail at 1.1 m
    assert radius_note(ControllerSpec("cmpc", flocking=False), 3, 0.01, "wedge", None) is None  # 1.2 m apart
    assert radius_note(_spec(), 4, 0.01, "wedge", None) is None  # arrived under the one d_flock
    assert radius_note(_spec(), 5, 0.01, "two_rows", None) is not None  # did not
    assert radius_note(_spec(), 3, 0.3, "auto", None) is None
    assert radius_note(_spec("orca"), 3, 0.01, "auto", None) is None
    assert radius_note(_spec(), 1, 0.01, "auto", None) is None
    assert radius_note(_spec(), 6, 0.01, "antipodal", None) is None  # goals metres apart: no spacing to give


def test_simulate_says_it_once_for_a_small_robot(capsys):
    args = ["simulate", "--controller", "cmpc", "--humans", "0", "--episodes", "1", "--no-progress"]
    assert main([*args, "--set", "world.radius=0.01"]) == 0
    assert capsys.readouterr().err.count("note: robots arrive within [world] radius 0.01 m") == 1
    assert main([*args, "--set", "world.radius=0.01", "--set", "env.robot_spacing=1.2", "--set",
                 "mpc.flock_distance=goals"]) == 0  # fmt: skip
    assert "[world] radius" not in capsys.readouterr().err


def test_a_python_users_own_goals_get_the_same_warning():
    """A layout of one's own has no formation for the note to read: the controller's reset warns with the
    note's rule, d_min within 0.05 m of the closest goals' distance or above (Table I's 0.8 m: goals 0.85 m
    apart warn, 0.86 m do not), naming the pair and d_min + 0.3 m. Measured: a row of 3 goals 0.8 m apart
    with nobody about, DMPC timed out; 0.6 m apart, both MPCs (standing 1.0 m apart)."""
    goals = np.array([[-0.85, 4.0], [0.0, 4.0], [0.86, 4.0]])
    message = (
        r"^robots 0 and 1's goals lie 0\.85 m apart, and the MPC keeps every pair of robots d_min 0\.8 m "
        r"apart \(Eq\. 12\), which can keep them from standing on their goals at once: the episode then "
        r"times out; goals 1\.1 m apart or more gave room"
    )
    with pytest.warns(GoalRoomWarning, match=message):
        warn_goal_room(MPCConfig(), goals)
    with warnings.catch_warnings():
        warnings.simplefilter("error", GoalRoomWarning)
        warn_goal_room(MPCConfig(), goals[1:])  # 0.86 m: 0.8 < 0.86 - 0.05
        warn_goal_room(MPCConfig(), goals[:1])  # one robot
        warn_goal_room(MPCConfig(d_min=0.6), goals)
    with pytest.warns(GoalRoomWarning, match="robots 0 and 1's goals lie 0.80 m apart"):
        controller = make_controller(ControllerSpec("dmpc"), EnvConfig())
        starts = np.array([[-1.0, -4.0], [0.0, -4.0], [1.0, -4.0]])
        layout = Layout(starts, starts * [0.8, -1.0], np.zeros((0, 2)), np.zeros((0, 2)))
        controller.reset(CrowdEnv(EnvConfig()).reset_layout(layout))
        controller.close()


def test_the_command_line_says_it_once_in_its_own_words(capsys):
    args = ["simulate", "--controller", "dmpc", "--humans", "0", "--episodes", "2", "--no-progress"]
    assert main([*args, "--set", "mpc.d_min=1.0", "--set", "env.time_limit=2"]) == 0
    err = capsys.readouterr().err
    assert err.count("note: the MPC's d_min 1 m is not well below") == 1 and "goals lie" not in err


def test_the_antipodal_circle_gets_the_note_too_without_a_spacing_it_refuses():
    """The controller's GoalRoomWarning, which simulate and sweep leave out for this note, fired for 12
    robots on the circle (neighbouring goals 7 sin(pi / 12) = 1.81 m apart) at d_min 1.8, and the note said
    nothing there."""
    note = goal_room_note(_spec(d_min=1.8), 12, "antipodal")
    assert note is not None and note.startswith("note: the MPC's d_min 1.8 m is not well below the 1.81")
    assert "(antipodal of 12)" in note and "robot_spacing" not in note
    assert goal_room_note(_spec(), 12, "antipodal") is None  # Table I's 0.8 m
