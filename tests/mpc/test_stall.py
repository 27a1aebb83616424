"""Stalled robots stop flocking (mpc/stall.py, StepData.flocking), on histories with answers known by hand."""

import numpy as np
import pytest

from mpc.config import MPCConfig, MPCConfigError
from mpc.nlp import StepData
from mpc.stall import StallWatch

GOALS = np.array([[0.0, 10.0], [1.0, 10.0], [2.0, 10.0]])


def _positions(y0: float, y1: float, y2: float) -> np.ndarray:
    return np.array([[0.0, y0], [1.0, y1], [2.0, y2]])


def test_a_robot_is_stalled_after_a_window_without_progress():
    """Window 1.2 s at tau = 0.4 s: three steps. Robot 0 walks 0.3 m a step, robot 1 creeps 0.05 m a step
    (0.15 m in the window, under 0.25 m), robot 2 stands still but has arrived."""
    watch = StallWatch(window_s=1.2, dt=0.4)
    arrived = np.array([False, False, True])
    for step in range(3):  # the window is not full yet: nobody is stalled
        stalled = watch.update(_positions(0.3 * step, 0.05 * step, 10.0), GOALS, arrived)
        np.testing.assert_array_equal(stalled, [False, False, False])
    stalled = watch.update(_positions(0.9, 0.15, 10.0), GOALS, arrived)
    np.testing.assert_array_equal(stalled, [False, True, False])
    # Robot 1 moves again: 0.15 -> 0.5 over the window is 0.35 m of progress.
    watch.update(_positions(1.2, 0.3, 10.0), GOALS, arrived)
    watch.update(_positions(1.5, 0.4, 10.0), GOALS, arrived)
    stalled = watch.update(_positions(1.8, 0.5, 10.0), GOALS, arrived)
    np.testing.assert_array_equal(stalled, [False, False, False])
    watch.reset()  # a new episode starts with an empty window
    np.testing.assert_array_equal(watch.update(_positions(0, 0, 0), GOALS, arrived), [False] * 3)


def test_moving_away_from_the_goal_is_no_progress():
    watch = StallWatch(window_s=0.4, dt=0.4)
    watch.update(_positions(0, 0, 0), GOALS, np.zeros(3, bool))
    stalled = watch.update(_positions(-1.0, 0.3, 0.2), GOALS, np.zeros(3, bool))
    np.testing.assert_array_equal(stalled, [True, False, True])


@pytest.mark.parametrize("args", [(0.0, 0.4), (1.0, 0.0), (-1.0, 0.4), (1.0, 0.4, 0.0), (1.0, 0.4, -0.25)])
def test_bad_windows_are_refused(args):
    with pytest.raises(ValueError, match="must be > 0"):
        StallWatch(*args)


def _data(**kw) -> StepData:
    return StepData(np.zeros((3, 4)), np.zeros((3, 2)), GOALS, active=np.ones(3, bool), **kw)


def test_flocking_weights_leave_out_every_pair_with_a_robot_that_does_not_flock():
    # Pairs (0,1), (0,2), (1,2) in pair_index order.
    np.testing.assert_array_equal(_data().floc_weights(10.0), [10.0, 10.0, 10.0])
    one_out = _data(flocking=np.array([True, True, False]))
    np.testing.assert_array_equal(one_out.floc_weights(10.0), [10.0, 0.0, 0.0])
    # Robot 1 does not flock and robot 2 has arrived: no pair is left.
    both = _data(arrived=np.array([False, False, True]), flocking=np.array([True, False, True]))
    np.testing.assert_array_equal(both.floc_weights(10.0), [0.0, 0.0, 0.0])


def test_the_release_window_is_validated_and_off_by_default():
    assert MPCConfig().stall_release_s == 0.0  # the paper: flocking never released
    with pytest.raises(MPCConfigError, match="stall_release_s must be >= 0"):
        MPCConfig(stall_release_s=-1.0)


def test_the_window_is_exactly_window_s_long():
    """Window 0.4 s at tau = 0.4 s: progress is measured over one step, however long the robot has run.
    Robot 0 walks 0.2 m a step: 0.2 < 0.25 per window, so it is stalled at every step once the window is
    full (over two steps it would have made 0.4 m)."""
    watch = StallWatch(window_s=0.4, dt=0.4)
    arrived = np.zeros(3, bool)
    watch.update(_positions(0.0, 0.0, 0.0), GOALS, arrived)
    for step in range(1, 5):
        stalled = watch.update(_positions(0.2 * step, 0.3 * step, 0.0), GOALS, arrived)
        np.testing.assert_array_equal(stalled, [True, False, True])


def test_progress_of_exactly_the_threshold_counts_as_moving_and_the_threshold_is_configurable():
    # 10 -> 9.75 m (exact in binary): 0.25 m is not "less than 0.25 m".
    watch = StallWatch(window_s=0.4, dt=0.4)
    watch.update(_positions(0.0, 0.0, 0.0), GOALS, np.zeros(3, bool))
    stalled = watch.update(_positions(0.25, 0.5, 0.0), GOALS, np.zeros(3, bool))
    np.testing.assert_array_equal(stalled, [False, False, True])
    # With progress = 0.6 m, neither 0.25 nor 0.5 m in the window is enough.
    watch = StallWatch(window_s=0.4, dt=0.4, progress=0.6)
    watch.update(_positions(0.0, 0.0, 0.0), GOALS, np.zeros(3, bool))
    stalled = watch.update(_positions(0.25, 0.5, 0.0), GOALS, np.zeros(3, bool))
    np.testing.assert_array_equal(stalled, [True, True, True])


def test_progress_is_towards_the_goal_the_robot_has_now():
    """With goals as slots a robot's goal can change. Distances stored per step compared the old goal with the
    new one: a robot parked on its slot and then driving 0.3 m a step to the neighbouring slot (1.2 m away)
    read as stalled, and one standing still read as moving once its new slot was 1.2 m nearer."""
    watch = StallWatch(window_s=4.0, dt=0.4)  # many_robots.toml's window: 10 steps
    old, new = np.array([[0.0, 5.0]]), np.array([[1.2, 5.0]])
    position = np.array([[0.0, 5.0]])
    for _ in range(12):
        watch.update(position, old, np.array([True]))
    for _ in range(4):
        position = position + [[0.3, 0.0]]
        assert not watch.update(position, new, np.array([False]))[0]
    watch.reset()
    still = np.zeros((1, 2))
    for _ in range(12):
        watch.update(still, np.array([[0.0, 5.0]]), np.array([False]))
    assert watch.update(still, np.array([[0.0, 3.8]]), np.array([False]))[0]


@pytest.mark.parametrize("window_s", [1e19, 1e308])
def test_a_window_longer_than_any_episode_never_stalls_a_robot(window_s):
    """stall_release_s is any finite number >= 0 (mpc/config.py); 1e19 s made the window's deque length
    overflow a C ssize_t (OverflowError when the controller was built), and 1e308 s / 0.4 s is inf, which
    round() could not make an int (the same OverflowError, from simulate --set mpc.stall_release_s=1e308)."""
    watch = StallWatch(window_s=window_s, dt=0.4)
    for _ in range(5):
        stalled = watch.update(_positions(0, 0, 0), GOALS, np.zeros(3, bool))
        np.testing.assert_array_equal(stalled, [False, False, False])


def test_a_window_shorter_than_half_a_step_is_one_step():
    """stall_release_s = 0.1 s at tau = 0.4 s rounds to no step at all; the window is one step, so a robot
    walking 0.3 m a step (over 0.25 m) is moving. Compared with itself it would have made 0 m: stalled."""
    watch = StallWatch(window_s=0.1, dt=0.4)
    assert watch.steps == 1
    arrived = np.zeros(3, bool)
    np.testing.assert_array_equal(watch.update(_positions(0, 0, 0), GOALS, arrived), [False] * 3)
    stalled = watch.update(_positions(0.3, 0.1, 0.0), GOALS, arrived)
    np.testing.assert_array_equal(stalled, [False, True, True])
