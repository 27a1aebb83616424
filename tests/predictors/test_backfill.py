"""predictors.backfill: the rows before a short track, extended back from it, by hand."""

import numpy as np
import pytest

from predictors.backfill import backfill


def test_a_short_track_is_extended_back_at_its_mean_step_and_the_others_are_kept():
    history = np.zeros((5, 4, 2))
    history[:, 0] = np.arange(5)[:, None] * [1.0, 0.0]  # observed throughout: kept
    history[:, 1] = 99.0
    history[2:, 1] = [[10.0, 0.0], [11.0, 1.0], [13.0, 1.0]]  # 3 positions: mean step (1.5, 0.5)
    history[:, 2] = -7.0
    history[-1, 2] = [5.0, 5.0]  # seen once: nothing is known of its motion
    history[:, 3] = 3.0  # observed for longer than the window
    before = history.copy()
    out = backfill(history, np.array([5, 3, 1, 40]))
    np.testing.assert_array_equal(out[:, 0], before[:, 0])
    np.testing.assert_allclose(out[:, 1], [[7.0, -1.0], [8.5, -0.5], [10.0, 0.0], [11.0, 1.0], [13.0, 1.0]])
    np.testing.assert_array_equal(out[:, 2], np.full((5, 2), 5.0))
    np.testing.assert_array_equal(out[:, 3], before[:, 3])
    np.testing.assert_array_equal(history, before)  # a new array


@pytest.mark.parametrize(
    "observed",
    [np.array([2, 0]), np.array([2]), np.array([2.0, 3.0]), np.array([[2, 3]])],
    ids=["zero", "too few", "floats", "2-D"],
)
def test_counts_that_are_not_one_positive_int_per_agent_are_refused(observed):
    with pytest.raises(ValueError, match=r"observed must be 2 ints >= 1 \(positions observed"):
        backfill(np.zeros((4, 2, 2)), observed)
