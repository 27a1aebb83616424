"""mpc/parked.py: a parked robot holds its goal no harder than the farthest teammate on its way."""

import numpy as np

from mpc.parked import yield_slack

GOALS = np.array([[0.0, 0.0], [1.2, 0.0], [0.0, 5.0]])


def test_parked_robots_are_softened_to_the_farthest_teammates_distance():
    # Robot 0 on its goal, robot 1 pushed 0.4 m off it, robot 2 still 3 m from its goal.
    positions = GOALS + [[0.0, 0.0], [0.4, 0.0], [0.0, -3.0]]
    slack = yield_slack(positions, GOALS, np.array([True, True, False]), radius=0.3)
    # D = 3 (robot 2; robot 1 at 0.4 m is away too, but nearer). Effective distance max(d_i, D) = 3 each.
    np.testing.assert_allclose(slack, [3.0, 2.6, 0.0])


def test_no_slack_once_everyone_is_within_its_radius_or_for_robots_that_never_arrived():
    positions = GOALS + [[0.0, 0.1], [0.2, 0.0], [0.0, -0.25]]
    np.testing.assert_array_equal(yield_slack(positions, GOALS, np.ones(3, bool), radius=0.3), [0, 0, 0])
    far = GOALS + [[0.0, -2.0], [0.0, -2.0], [0.0, -4.0]]
    np.testing.assert_array_equal(yield_slack(far, GOALS, np.zeros(3, bool), radius=0.3), [0, 0, 0])


def test_a_robot_exactly_on_its_radius_has_not_arrived_and_is_yielded_to():
    # The simulator counts a goal reached strictly within the radius (crowdsim/env.py), so robot 1 exactly
    # 0.5 m from its goal (radius 0.5) is still on its way: D = 0.5 and robot 0, on its goal, gets slack 0.5.
    positions = GOALS + [[0.0, 0.0], [0.0, -0.5], [0.0, 0.0]]
    slack = yield_slack(positions, GOALS, np.array([True, False, True]), radius=0.5)
    np.testing.assert_array_equal(slack, [0.5, 0.0, 0.5])
