"""benchmarks/replay_prediction.py: the predictors among a replayed crowd, open loop, scored on the people
tracked through the horizon, by how long they had been tracked."""

import sys

import numpy as np
import pytest

from crowdsim.replay import Recording
from predictors.registry import load_predictor
from tests.benchmark_modules import load_benchmark
from tests.predictors.samples import shared_data_dir

replay_prediction = load_benchmark("replay_prediction")


def walkers():
    """Frames 0..54 (10 rows). Person 1 walks +x 0.4 m a row on every row; person 2 appears at row 6 and
    walks -y 0.2 m a row to the end."""
    rows = [(6 * r, 1, 0.4 * r, 0.0) for r in range(10)] + [
        (6 * r, 2, 3.0, -0.2 * (r - 6)) for r in range(6, 10)
    ]
    return Recording.from_rows("eth", np.array(rows), frame_step=6)


def test_each_case_holds_the_rows_before_a_track_and_its_length():
    cases = replay_prediction.cases(walkers(), obs_len=3, horizon=2, every=1)
    # rows 2..7 have two rows of past and two of future on the grid
    assert len(cases) == 6
    history, run, future = cases[4]  # row 6: person 2 just came
    np.testing.assert_array_equal(run, [7, 1])
    np.testing.assert_allclose(history[:, 1], [[3.0, 0.0]] * 3)  # held where its track begins
    np.testing.assert_allclose(future[:, 1], [[3.0, -0.2], [3.0, -0.4]])
    history, run, _ = cases[5]  # row 7: tracked for 2 rows, the row before held
    np.testing.assert_array_equal(run, [8, 2])
    np.testing.assert_allclose(history[:, 1], [[3.0, 0.0], [3.0, 0.0], [3.0, -0.2]])


def test_constant_velocity_is_exact_on_straight_walks_once_it_has_seen_two_rows():
    cases = replay_prediction.cases(walkers(), obs_len=3, horizon=2, every=1)
    ade, fde, run = replay_prediction.errors(load_predictor("constant_velocity"), cases, horizon=2)
    assert len(ade) == len(run) == 8  # person 1 at six rows, person 2 at its two with a whole future
    np.testing.assert_allclose(ade[run >= 2], 0.0, atol=1e-12)
    # just come, it stands: 0.2 and 0.4 m behind
    np.testing.assert_allclose((ade[run == 1], fde[run == 1]), ([0.3], [0.4]))


def test_it_prints_every_group_for_each_predictor(monkeypatch, capsys):
    root = shared_data_dir()
    if root is None:
        pytest.skip("shared data (../shared/data or $CROWDMPC_DATA) not available")
    monkeypatch.setenv("CROWDMPC_DATA", str(root))
    argv = [
        "replay_prediction.py",
        "--crowd",
        "hotel_test",
        "--predictors",
        "constant_velocity",
        "--every",
        "20",
    ]
    monkeypatch.setattr(sys, "argv", argv)
    replay_prediction.main()
    out = capsys.readouterr().out.splitlines()
    assert out[1].split() == ["predictor", ">=", "9", "2..8", "1", "all"]
    assert out[2].startswith("constant_velocity") and out[3].startswith("people scored: >= 9 ")
