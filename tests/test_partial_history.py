"""benchmarks/partial_history.py: what each fill hands the predictor, and the errors it scores, by hand."""

import numpy as np
import pytest

from tests.benchmark_modules import load_benchmark

partial_history = load_benchmark("partial_history")


class Recorder:
    """A predictor reading 4 positions that predicts everyone standing at the origin, keeping what it got."""

    obs_len = 4

    def rollout(self, history, mask, robots_future, humans, horizon):
        self.history, self.mask = history.copy(), mask.copy()
        return np.zeros((horizon, len(humans), 2))


def scene():
    """Agent 0 walks +1 m a step along x from x = 0; agent 1 stands at (0, 5). 4 observed + 2 future steps."""
    xy = np.zeros((6, 2, 2))
    xy[:, 0, 0] = np.arange(6.0)
    xy[:, 1] = [0.0, 5.0]
    return xy


@pytest.mark.parametrize(
    "tracked, fill, rows, seen",
    [
        (None, "all", [0.0, 1.0, 2.0, 3.0], [True] * 4),
        (2, "standing", [2.0, 2.0, 2.0, 3.0], [True] * 4),
        (2, "backfill", [0.0, 1.0, 2.0, 3.0], [True] * 4),
        (2, "mask", [0.0, 0.0, 2.0, 3.0], [False, False, True, True]),
    ],
)
def test_each_fill_hands_the_predictor_its_rows_and_scores_the_primary(tracked, fill, rows, seen):
    predictor = Recorder()
    ade, fde = partial_history.primary_errors(predictor, scene(), tracked, fill)
    np.testing.assert_array_equal(predictor.history[:, 0, 0], rows)
    np.testing.assert_array_equal(predictor.mask[:, 0], seen)
    np.testing.assert_array_equal(predictor.history[:, 1], np.tile([0.0, 5.0], (4, 1)))  # the others: as seen
    assert (ade, fde) == (4.5, 5.0)  # predicted at the origin, truly at x = 4 and 5
