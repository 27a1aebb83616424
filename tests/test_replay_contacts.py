"""benchmarks/replay_contacts.py: each contact's speeds and place among a replayed crowd, counting only the
people tracked then."""

import math
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from tests.benchmark_modules import load_benchmark
from tests.predictors.samples import shared_data_dir

replay_contacts = load_benchmark("replay_contacts")


def episode(present):
    """One robot from (0, 0) up to (0, 0.4) and on, goal (0, 5); a person walking down x = 0.5 at 1 m/s,
    0.5 m from the robot at row 1 (contact), and one standing on the robot's start, tracked as ``present``."""
    robot = np.array([[[0.0, 0.0]], [[0.0, 0.4]], [[0.0, 0.8]]])
    walker = [[0.5, 0.8], [0.5, 0.4], [0.5, 0.0]]
    humans = np.array([[w, [0.0, 0.0]] for w in walker])
    return SimpleNamespace(
        robot_positions=robot,
        human_positions=humans,
        robot_goals=np.array([[0.0, 5.0]]),
        human_present=present,
    )


def test_the_contact_is_the_closest_tracked_approach_with_its_speeds_and_place():
    walking_only = np.array([[True, False]] * 3)
    human, robot, start, goal, appeared = replay_contacts.contact_at(episode(walking_only))
    # closest at row 1: 0.5 m; each moved 0.4 m in the 0.4 s before
    assert (human, robot) == pytest.approx((1.0, 1.0)) and (start, goal) == pytest.approx((0.4, 4.6))
    assert appeared == 0.0  # tracked from the first state, 1.0 m from the robot then
    # the person standing on the start is not there: untracked, no contact with it
    assert replay_contacts.contact_at(episode(np.array([[False, False]] * 3))) is None
    human, robot, _, _, _ = replay_contacts.contact_at(episode(np.array([[False, True]] * 3)))
    assert math.isnan(human) and robot == 0.0  # tracked, it is the contact: at row 0, with no step before
    # a track that begins at the contact has no speed: its row before is padding (it read 0 m/s, standing)
    late = np.array([[False, False], [True, False], [True, False]])
    human, robot, _, _, appeared = replay_contacts.contact_at(episode(late))
    assert math.isnan(human) and robot == pytest.approx(1.0) and appeared == 1.0


def test_a_contact_with_someone_whose_track_begins_within_contact_is_told_apart():
    # the walker's track begins at row 1, 0.5 m from the robot: the contact came with the person
    appears = np.array([[False, False], [True, False], [True, False]])
    assert replay_contacts.contact_at(episode(appears))[4] == 1.0
    # a track that began at row 1 out of contact (the robot 2 m away then) is an ordinary contact
    far = episode(appears)
    far.robot_positions = far.robot_positions.copy()
    far.robot_positions[1] = [[0.0, -1.6]]
    far.robot_positions[2] = [[0.2, 0.0]]
    assert replay_contacts.contact_at(far)[4] == 0.0


def run_main(monkeypatch, capsys, crowd: str) -> list[str]:
    """The benchmark's lines for 3 people of ``crowd``, 1 episode a scenario (skipped without the data)."""
    root = shared_data_dir()
    if root is None:
        pytest.skip("shared data (../shared/data or $CROWDMPC_DATA) not available")
    monkeypatch.setenv("CROWDMPC_DATA", str(root))
    argv = ["replay_contacts.py", "--crowd", crowd, "--humans", "3", "--episodes", "1"]
    monkeypatch.setattr(sys, "argv", argv)
    replay_contacts.main()
    return capsys.readouterr().out.splitlines()


def test_it_runs_and_reports_each_scenario(monkeypatch, capsys):
    out = run_main(monkeypatch, capsys, "eth_test")
    assert out[0] == "CMPC with constant_velocity among 3 people of eth_test, 1 episode each"
    assert [line.split()[0] for line in out[1:]] == ["circle", "perpendicular"]
    assert all(" of 1 episode" in line and " of 1 episodes" not in line for line in out[1:])


def test_how_far_people_were_pushed_counts_tracked_people_over_the_steps_both_ran():
    plain = episode(np.array([[True, True]] * 3))
    pushed = SimpleNamespace(**{**plain.__dict__, "human_positions": plain.human_positions.copy()})
    pushed.human_positions[1, 0] += [0.3, 0.0]
    pushed.human_positions[2, 1] += [0.0, 0.9]  # the standing person, untracked at row 2
    pushed.human_present = np.array([[True, True], [True, True], [True, False]])
    assert replay_contacts.deflection(pushed, plain) == pytest.approx(0.3)
    shorter = SimpleNamespace(
        human_positions=plain.human_positions[:1], human_present=plain.human_present[:1]
    )
    assert replay_contacts.deflection(pushed, shorter) == 0.0


def test_among_a_reactive_crowd_it_says_how_far_people_were_pushed(monkeypatch, capsys):
    out = run_main(monkeypatch, capsys, "eth_test_reactive")
    assert [line.split()[0] for line in out[1:]] == ["circle", "circle", "perpendicular", "perpendicular"]
    assert "people pushed off their tracks: by more than 0.1 m in " in out[1]


def test_no_people_is_refused_in_one_line_before_any_episode(monkeypatch, capsys):
    # an empty crowd has no closest approach: the script ended in numpy's traceback after its episodes
    monkeypatch.setattr(sys, "argv", ["replay_contacts.py", "--humans", "0", "--episodes", "1"])
    with pytest.raises(SystemExit) as exit_:
        replay_contacts.main()
    assert exit_.value.code == 2
    assert capsys.readouterr().err.splitlines()[-1] == (
        "replay_contacts.py: error: argument --humans: humans must be an integer in 1..50, got '0'"
    )
