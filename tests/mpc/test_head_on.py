"""Exact head-on ties between robots (mpc/head_on.py): who is in one, where their targets move, and that two
robots swapping places pass each other in the closed loop under both controllers."""

import numpy as np
import pytest

from mpc.head_on import NUDGE, head_on, keep_right, mirrored
from mpc.step_data import StepData

SWAP = np.array([[-4.0, 0.0], [4.0, 0.0]])


def test_a_swap_along_a_line_is_a_tie_and_each_robot_keeps_right_by_hand():
    """Robot 0 heads +x (its right is -y), robot 1 heads -x (its right is +y): each target moves NUDGE (3
    cm) to its robot's right, so the robots pass right shoulder to right shoulder."""
    targets = SWAP[::-1].copy()
    np.testing.assert_array_equal(head_on(SWAP, targets), [True, True])
    np.testing.assert_allclose(keep_right(SWAP, targets), [[4.0, -NUDGE], [-4.0, NUDGE]], rtol=0, atol=1e-15)
    diagonal = np.array([[0.0, 0.0], [3.0, 3.0]])  # along y = x: still a tie, nudged at right angles
    moved = keep_right(diagonal, diagonal[::-1].copy()) - diagonal[::-1]
    np.testing.assert_allclose(moved, NUDGE / np.sqrt(2) * np.array([[1.0, -1.0], [-1.0, 1.0]]), atol=1e-15)


@pytest.mark.parametrize(
    ("positions", "targets", "tied"),
    [
        ([[-4.0, 0.0], [4.0, 1e-6]], [[4.0, 0.0], [-4.0, 1e-6]], [False, False]),  # not exact: no tie
        ([[-4.0, 0.0], [-2.0, 0.0]], [[4.0, 0.0], [6.0, 0.0]], [False, False]),  # one behind the other
        ([[-4.0, 0.0], [4.0, 0.0]], [[4.0, 0.0], [4.0, 0.0]], [False, False]),  # robot 1 on its target
        ([[-4.0, 0.0], [4.0, 0.0]], [[-6.0, 0.0], [6.0, 0.0]], [False, False]),  # back to back
        ([[0.0, 0.0], [5.0, 0.0]], [[1.0, 0.0], [4.0, 0.0]], [False, False]),  # towards, stopping 3 m apart
        # the paper's row after an overshoot: its outer robots head back inwards to goals 2 m apart
        ([[-1.01, 5.0], [0.0, 5.0], [1.01, 5.0]], [[-1.0, 5.0], [0.0, 5.0], [1.0, 5.0]], [False] * 3),
        # robots 0 and 2 meet on y = 0; robot 1 crosses their line at right angles
        ([[-4.0, 0.0], [0.0, -4.0], [4.0, 0.0]], [[4.0, 0.0], [0.0, 4.0], [-4.0, 0.0]], [True, False, True]),
    ],
)
def test_who_is_in_a_tie(positions, targets, tied):
    np.testing.assert_array_equal(head_on(np.array(positions), np.array(targets)), tied)
    untouched = np.array(targets, dtype=float)
    if not any(tied):
        assert keep_right(np.array(positions), untouched) is untouched


def test_step_data_hands_the_nlps_the_nudged_targets():
    """Every NLP reads Eq. 8's targets through StepData.reference_targets: the goals, nudged in a tie."""
    states = np.concatenate([SWAP, np.zeros((2, 2))], axis=1)
    data = StepData(states, np.zeros((2, 2)), SWAP[::-1].copy(), np.ones(2, bool))
    np.testing.assert_allclose(data.reference_targets(), [[4.0, -NUDGE], [-4.0, NUDGE]], atol=1e-15)
    lanes = [[0.0, 0.0], [0.0, 0.5]]  # robot 1 in a lane of its own, 0.5 m to the side
    apart = StepData(
        states + np.pad(lanes, ((0, 0), (0, 2))), np.zeros((2, 2)), SWAP[::-1] + lanes, np.ones(2, bool)
    )
    np.testing.assert_array_equal(apart.reference_targets(), SWAP[::-1] + lanes)


def test_mirror_images_on_crossing_paths_are_a_tie_and_parallel_ones_are_not():
    """Two robots crossing at right angles from the same distance mirror each other across y = x (DMPC's
    Jacobi update then moved them alike until they went through each other); the paper's row, whose outer
    robots mirror each other across x = 0 on parallel paths, is no tie; nor are moving mirror images whose
    velocities do not mirror. Each robot of the crossing pair keeps right: robot 0 heads +x (right is -y),
    robot 1 heads +y (right is +x)."""
    still = np.zeros((2, 2))
    crossing, goals = np.array([[-4.0, 0.0], [0.0, -4.0]]), np.array([[4.0, 0.0], [0.0, 4.0]])
    np.testing.assert_array_equal(mirrored(crossing, goals, still), [True, True])
    np.testing.assert_array_equal(head_on(crossing, goals), [False, False])
    np.testing.assert_allclose(
        keep_right(crossing, goals, still), [[4.0, -NUDGE], [NUDGE, 4.0]], rtol=0, atol=1e-15
    )
    row = np.array([[-1.0, -5.0], [0.0, -5.0], [1.0, -5.0]])
    np.testing.assert_array_equal(mirrored(row, row + [0.0, 10.0], np.zeros((3, 2))), [False] * 3)
    moving = np.array([[1.0, 0.0], [0.0, 0.5]])  # robot 0 at 1 m/s along its path, robot 1 at 0.5 m/s
    np.testing.assert_array_equal(mirrored(crossing, goals, moving), [False, False])
    np.testing.assert_array_equal(mirrored(crossing, goals, np.array([[1.0, 0.0], [0.0, 1.0]])), [True, True])
