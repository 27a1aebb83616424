"""Guidance around standing humans (mpc/guidance.py), on layouts whose answer is known by hand."""

import numpy as np
import pytest

from mpc.guidance import LOOKAHEAD, guidance_targets, segment_distances


def test_segment_distances_by_hand():
    a, b = np.array([0.0, 0.0]), np.array([4.0, 0.0])
    points = np.array([[2.0, 1.0], [-3.0, 4.0], [5.0, 0.0], [0.0, 0.0]])
    np.testing.assert_allclose(segment_distances(a, b, points), [[1.0, 5.0, 1.0, 0.0]])


def test_a_free_line_keeps_the_goal():
    positions, goals = np.array([[0.0, -5.0]]), np.array([[0.0, 5.0]])
    standing = np.array([[2.0, 0.0], [-2.0, 0.0]])  # 2 m either side of the line: clear at 1 m
    np.testing.assert_array_equal(guidance_targets(positions, goals, standing, 1.0), goals)
    np.testing.assert_array_equal(guidance_targets(positions, goals, np.zeros((0, 2)), 1.0), goals)


def test_a_row_across_the_line_is_walked_around_at_its_near_end():
    """A row of humans 1 m apart on y = 0 from x = -4 to x = 2 (discs of 0.9 m overlap: a wall). The robot at
    (0, -3) heads for (0, 3): the short way round is the row's right end, x = 2 + 0.9."""
    standing = np.stack([np.arange(-4.0, 2.5, 1.0), np.zeros(7)], axis=1)
    target = guidance_targets(np.array([[0.0, -3.0]]), np.array([[0.0, 3.0]]), standing, 0.9)[0]
    heading = target - [0.0, -3.0]
    assert heading[0] > 0 and np.linalg.norm(heading) >= LOOKAHEAD - 1e-9
    # The corner it heads for is the ring node past the right end: its line is clear of every disc.
    assert segment_distances(np.array([0.0, -3.0]), target, standing).min() >= 0.9 - 1e-9
    # The mirror image goes round the other end.
    mirrored = guidance_targets(np.array([[-2.0, -3.0]]), np.array([[-2.0, 3.0]]), standing * [-1, 1], 0.9)
    assert mirrored[0, 0] < -2.0


def test_no_detour_where_none_can_help_or_for_a_parked_robot():
    standing = np.array([[0.0, 0.0], [0.0, 3.0]])
    positions, goals = np.array([[0.0, -3.0], [0.2, -3.0]]), np.array([[0.0, 3.2], [0.2, 6.0]])
    targets = guidance_targets(positions, goals, standing, 0.9, active=np.array([True, False]))
    np.testing.assert_array_equal(targets, goals)  # robot 0's goal is inside a disc; robot 1 is not guided
    # A disc the robot already stands in does not block it.
    inside = guidance_targets(np.array([[0.0, -0.5]]), np.array([[0.0, -5.0]]), standing, 0.9)
    np.testing.assert_array_equal(inside, [[0.0, -5.0]])


@pytest.mark.parametrize("clearance", [0.0, -1.0])
def test_no_clearance_no_guidance(clearance):
    goals = np.array([[0.0, 3.0]])
    np.testing.assert_array_equal(
        guidance_targets(np.zeros((1, 2)), goals, np.array([[0.0, 1.0]]), clearance), goals
    )
