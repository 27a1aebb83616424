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
    scores = replay_prediction.errors(load_predictor("constant_velocity"), cases, horizon=2)
    ade, fde, run = scores.ade, scores.fde, scores.run
    assert len(ade) == len(run) == 8  # person 1 at six rows, person 2 at its two with a whole future
    np.testing.assert_allclose(ade[run >= 2], 0.0, atol=1e-12)
    # just come, it stands: 0.2 and 0.4 m behind
    np.testing.assert_allclose((ade[run == 1], fde[run == 1]), ([0.3], [0.4]))
    # rows 2..7 in order, person 1 then 2 at each: person 1 walks 1 m/s; person 2 is 0 m/s just come (row 6,
    # predicted to stand, it went 0.4 m: 0.4 short), 0.5 m/s once seen twice
    np.testing.assert_allclose(scores.speed, [1.0] * 5 + [0.0, 1.0, 0.5])
    np.testing.assert_allclose(scores.overshoot, [0.0] * 5 + [-0.4, 0.0, 0.0], atol=1e-12)


def test_by_speed_groups_the_people_tracked_long_enough_by_how_fast_they_went():
    scores = replay_prediction.Scores(
        ade=np.array([0.1, 0.2, 0.3, 0.4]),
        fde=np.zeros(4),
        run=np.array([9, 9, 3, 12]),
        speed=np.array([0.2, 1.5, 1.7, 1.49]),
        overshoot=np.zeros(4),
    )
    groups = replay_prediction.SPEEDS
    picked = [replay_prediction.grouped(scores, "speed", g).nonzero()[0].tolist() for g in groups.values()]
    assert picked == [[0], [], [3], [1]]  # the third, tracked 3 rows, is in none


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
    monkeypatch.setattr(sys, "argv", [*argv, "--by", "speed"])
    replay_prediction.main()
    out = capsys.readouterr().out.splitlines()
    assert out[1].split() == ["predictor", "<", "0.5", "0.5..1", "1..1.5", ">=", "1.5"]
    assert out[3].startswith("people scored: < 0.5 ")


def test_the_orca_oracle_is_refused_in_one_line_before_the_recording_is_read(monkeypatch, capsys):
    # it reads the simulator's state: the table's header came first, then its API's "call observe(obs)"
    argv = ["replay_prediction.py", "--predictors", "constant_velocity", "orca_oracle"]
    assert _refusal(monkeypatch, capsys, argv) == (
        "replay_prediction.py: error: argument --predictors: orca_oracle predicts the simulator's humans "
        "from its ORCA state, not a recording's people: name a predictor that reads positions"
    )


def _refusal(monkeypatch, capsys, argv: list[str]) -> str:
    """The one line ``argv`` is refused with (exit 2), nothing on standard output."""
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as exit_:
        replay_prediction.main()
    assert exit_.value.code == 2
    out, err = capsys.readouterr()
    assert out == ""
    return err.splitlines()[-1]


def test_a_predictor_named_twice_is_refused_before_the_recording_is_read(monkeypatch, capsys):
    """--predictors constant_velocity constant_velocity scored the recording twice and printed the row twice
    (the other benchmarks refuse a repeated row when parsed, bench_cli.check_distinct)."""
    argv = [
        "replay_prediction.py",
        "--predictors",
        "constant_velocity",
        "social_lstm_eth",
        "constant_velocity",
    ]
    assert _refusal(monkeypatch, capsys, argv) == (
        "replay_prediction.py: error: --predictors names constant_velocity more than once"
    )
