"""benchmarks/partial_history.py: what each fill hands the predictor, and the errors it scores, by hand."""

import re
import sys

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


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--predictor", "orca_oracle"], "--predictor orca_oracle: .* dataset scenes do not have"),
        (
            ["--tracked", "2", "9"],
            "--tracked 9: social_lstm_eth reads 9 positions, so a partial track is 1..8",
        ),
        (["--predictor", "constant_velocity", "--tracked", "2"], r"--tracked 2: .* is 1\.\.1$"),
        (["--tracked", "2", "2"], "--tracked names 2 more than once"),
    ],
)
def test_what_cannot_be_scored_is_refused_by_name(argv, message, monkeypatch, capsys):
    """The oracle was refused as reading one position (its real want, the simulator's state, unsaid), and a
    --tracked k at or past obs_len was dropped from the table without a word."""
    monkeypatch.setattr(sys, "argv", ["partial_history.py", *argv])
    with pytest.raises(SystemExit) as exit_:
        partial_history.main()
    assert exit_.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()[-1:]
    assert re.search(message, line), line
