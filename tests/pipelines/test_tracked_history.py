"""A tracker's late arrival (``obs.human_observed`` below the predictor's ``obs_len``): the MPC's predictor
reads the track extended back, not the padding; the simulator's observations (None) are read as they are."""

import numpy as np
import pytest

from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.mpc_setup import predictor_history
from tests.pipelines.test_motion_margins import _late_human


def test_the_padding_before_a_short_track_becomes_the_track_extended_back():
    # the human: padded at (0, 2.5) in rows 0-7, then (0, 2.0); tracked 2 positions -> 0.5 m a step along -y
    history, mask = predictor_history(_late_human(50, np.array([2])), 9)
    np.testing.assert_allclose(history[:, 3], [[0.0, 2.5 + 0.5 * (7 - t)] for t in range(8)] + [[0.0, 2.0]])
    observation = _late_human(50)
    np.testing.assert_array_equal(history[:, :3], observation.history[:, :3])  # robots: their own odometry
    assert mask.all()
    np.testing.assert_array_equal(predictor_history(observation, 9)[0], observation.history)  # None: as is


def test_a_social_lstm_predicts_the_late_arrival_walking_at_its_tracked_speed():
    """Padded, the tracked 0.5 m a step read as a start from standing: 0.15 m a step predicted."""
    controller = make_controller(ControllerSpec("cmpc", "social_lstm_eth"))
    steps = {}
    for observed in (None, np.array([2])):
        obs = _late_human(50, observed)
        controller.reset(obs)
        prediction = controller.act(obs).prediction[:, 0]
        steps[observed is None] = np.linalg.norm(np.diff(prediction, axis=0), axis=1).mean()
    assert steps[False] == pytest.approx(0.5, abs=0.05) and steps[True] < 0.2


def test_a_count_below_one_is_refused_naming_the_human():
    with pytest.raises(PipelineError, match=r"human_observed must be >= 1 .* got 0 for human 0"):
        predictor_history(_late_human(50, np.array([0])), 9)


def _with_nan_past(observed=None):
    """The late human's rows before its track as NaN, as many trackers give them."""
    obs = _late_human(50, observed)
    obs.history[:-2, 3] = np.nan
    return obs


def test_nan_rows_before_a_track_are_read_with_its_length_and_named_without_it():
    """Without human_observed the refusal came from the predictor, about a `mask` an Observation has not."""
    history, _ = predictor_history(_with_nan_past(np.array([2])), 9)
    assert np.isfinite(history).all()  # backfilled: the track extended back
    with pytest.raises(PipelineError) as refused:
        predictor_history(_with_nan_past(), 9)
    assert str(refused.value) == (
        "obs.history[-9] holds a position that is not finite for human 0 (7 such entries in the rows the "
        "predictor reads): give obs.human_observed, each human's track length (the rows before a track may "
        "then hold anything), or fill those rows with finite positions"
    )
    assert np.isfinite(predictor_history(_with_nan_past(), 2)[0]).all()  # a predictor reading 2 rows: fine


def test_nan_rows_inside_a_track_or_of_a_robot_are_named_as_such():
    """Both were told to give obs.human_observed: a robot has no track length, and one was given already."""
    with pytest.raises(PipelineError) as refused:
        predictor_history(_with_nan_past(np.array([4])), 9)  # rows -9..-3 NaN, the track rows -4..-1
    assert str(refused.value) == (
        "obs.history[-4] holds a position that is not finite for human 0 (2 such entries in the rows the "
        "predictor reads): that row is within its track of 4 (obs.human_observed): fill it, or give a "
        "shorter track"
    )
    obs = _late_human(50)
    obs.history[-5, 0] = np.nan
    with pytest.raises(PipelineError) as refused:
        predictor_history(obs, 9)
    assert str(refused.value) == (
        "obs.history[-5] holds a position that is not finite for robot 0 (1 such entry in the rows the "
        "predictor reads): a robot's rows must hold its positions"
    )


def test_a_current_position_that_is_not_finite_is_said_so():
    from pipelines.loop.mpc_setup import check_history

    obs = _late_human(50)
    obs.human_positions[0] = np.nan
    obs.history[-1, 3] = np.nan
    with pytest.raises(
        PipelineError, match=r"^obs.human_positions holds a position that is not finite \(human 0"
    ):
        check_history(obs)


def _taken_or_refused(field: str, value: np.ndarray, message: str | None) -> None:
    """Both checks of a hand-built observation (the MPC's, ORCA's) take ``field`` = ``value`` (``message``
    None), or refuse it in ``message``'s words exactly."""
    import dataclasses

    from pipelines.loop.mpc_setup import check_history
    from pipelines.loop.observed import check_state

    obs = dataclasses.replace(_late_human(50), **{field: value})
    for check in (check_history, check_state):
        if message is None:
            check(obs)
            continue
        with pytest.raises(PipelineError) as refused:
            check(obs)
        assert str(refused.value) == message


@pytest.mark.parametrize(
    ("present", "got"),
    [
        (np.ones(2, dtype=bool), "got bool of shape (2,)"),
        (np.ones((1, 2), dtype=bool), "got bool of shape (1, 2)"),
        (np.array([1.0]), None),
        (np.array([0.5]), "got float64 of shape (1,): [0.5]"),
    ],
)
def test_human_present_is_one_boolean_per_human(present, got):
    """Two Trues for one human passed as every human tracked (np.all), and 0.5 as tracked."""
    said = "obs.human_present must be 1 boolean, one per human (tracked now or not), "
    _taken_or_refused("human_present", present, None if got is None else said + got)


@pytest.mark.parametrize(
    ("reached", "got"),
    [
        (np.array([True, False, False]), None),
        (np.array([1, 0, 0]), None),  # a hand-built array of ints: taken, as human_present's
        (np.array([0.5, 0.0, 0.0]), "got float64: [0.5, 0.0, 0.0]"),
        (np.array([2, 0, 0]), "got int64: [2, 0, 0]"),
    ],
)
def test_robot_reached_is_one_boolean_per_robot(reached, got):
    """0.5 or 2 (a distance, a count) read as arrived (the MPC took ``bool`` of each) and the robot held
    position; 0/1 ints stay taken."""
    said = "obs.robot_reached must be one boolean per robot (has it been within obs.radius of its goal), "
    _taken_or_refused("robot_reached", reached, None if got is None else said + got)
