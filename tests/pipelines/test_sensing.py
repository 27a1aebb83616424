"""RangeLimited: a controller fed the humans within a radius of some robot, with a tracker's tracks."""

import re

import numpy as np
import pytest

from crowdsim.env import Observation
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode
from pipelines.loop.sensing import RangeLimited


def observation(step, humans, history_len=4):
    """One robot at the origin and humans at ``humans`` (N, 2), each walked +0.1 m a step along x to there."""
    humans = np.asarray(humans, dtype=float)
    agents = np.concatenate([[[0.0, 0.0]], humans])
    walk = np.zeros((history_len, len(agents), 2))
    walk[:, 1:, 0] = 0.1 * np.arange(-history_len + 1, 1)[:, None]
    n = len(humans)
    return Observation(
        time=0.4 * step, step=step, robot_positions=agents[:1], robot_velocities=np.zeros((1, 2)),
        robot_goals=np.array([[5.0, 0.0]]), robot_last_actions=np.zeros((1, 2)),
        robot_reached=np.zeros(1, bool),
        human_positions=humans, human_velocities=np.tile([0.25, 0.0], (n, 1)), human_goals=humans + 1.0,
        history=agents[None] + walk, radius=0.3, dt=0.4,
    )  # fmt: skip


class Keep:
    """A controller that keeps what it was handed."""

    name, predictor = "keep", None

    def reset(self, obs):
        self.seen = obs

    def act(self, obs):
        from crowdsim.control import ControlOutput

        self.seen = obs
        return ControlOutput(accelerations=np.zeros((obs.n_robots, 2)), extra={"own": 1})

    def describe(self):
        return {"predictor_sha256": None, "config": {"own": 2}}

    def close(self):
        pass


def test_only_the_humans_in_range_are_seen_with_their_tracks_padded_and_counted():
    sensor = RangeLimited(Keep(), radius=3.0)
    far, near = [5.0, 0.0], [0.0, 2.5]
    first = observation(10, [[1.0, 0.0], far, near])
    sensor.reset(first)
    seen = sensor.inner.seen
    np.testing.assert_array_equal(seen.human_positions, [[1.0, 0.0], near])
    # in view from the episode's start: tracked through the whole history, which is kept
    np.testing.assert_array_equal(seen.human_observed, [4, 4])
    np.testing.assert_array_equal(seen.history, first.history[:, [0, 1, 3]])
    # two steps later the far human has come near and the first left: a new track, a longer one, one gone
    out = sensor.act(observation(12, [[9.0, 0.0], [2.0, 0.0], near]))
    seen = sensor.inner.seen
    np.testing.assert_array_equal(seen.human_positions, [[2.0, 0.0], near])
    np.testing.assert_array_equal(seen.human_observed, [1, 6])
    np.testing.assert_allclose(seen.history[:, 1], np.tile([2.0, 0.0], (4, 1)))  # padded with where it is
    np.testing.assert_allclose(seen.history[:, 2, 0], [-0.3, -0.2, -0.1, 0.0])  # as walked
    np.testing.assert_array_equal(seen.history[:, 0], 0.0)  # the robot's own rows as they are
    assert out.extra == {"own": 1, "visible": [1, 2], "tracked": [1, 6]} and out.prediction is None
    sensor.act(observation(13, [[1.0, 0.0], [2.0, 0.0], near]))
    seen = sensor.inner.seen
    np.testing.assert_array_equal(seen.human_observed, [1, 2, 7])  # the first is back: a new track
    np.testing.assert_allclose(seen.history[:, 2, 0], [1.9, 1.9, 1.9, 2.0])  # tracked 2 of 4 rows


class Predicting(Keep):
    """Keep, predicting each human it is handed to stay where it is, at 2 steps and 3 IBR iterations."""

    def act(self, obs):
        import dataclasses

        out = super().act(obs)
        held = np.repeat(obs.human_positions[None], 2, axis=0)
        return dataclasses.replace(out, prediction=held, iteration_predictions=(held, held + 1.0, held))


def test_the_prediction_of_the_humans_in_view_goes_back_to_their_places_nan_for_the_others():
    """It was dropped (None): a recording behind a sensor showed no prediction, calibration scored none."""
    sensor = RangeLimited(Predicting(), radius=3.0)
    obs = observation(10, [[1.0, 0.0], [5.0, 0.0], [0.0, 2.5]])
    sensor.reset(obs)
    out = sensor.act(obs)
    expected = np.array([[[1.0, 0.0], [np.nan, np.nan], [0.0, 2.5]]] * 2)
    np.testing.assert_array_equal(out.prediction, expected)
    assert len(out.iteration_predictions) == 3
    np.testing.assert_array_equal(out.iteration_predictions[1], expected + 1.0)
    assert out.extra["visible"] == [0, 2]
    assert out.extra["tracked"] == [4, 4]  # seen through the whole history of 4 positions
    # through the loop's contract, which refuses a NaN anywhere but in a whole human's rows
    from pipelines.loop.contract import checked_output

    assert checked_output(sensor, out, obs) is not None


def test_without_reported_tracks_the_padding_reads_as_the_past_and_the_description_says_so():
    sensor = RangeLimited(Keep(), radius=3.0, report_tracks=False)
    sensor.reset(observation(10, [[1.0, 0.0]]))
    assert sensor.inner.seen.human_observed is None
    assert sensor.act(observation(11, [[1.0, 0.0]])).extra["tracked"] is None  # as the controller was told
    assert sensor.describe()["config"] == {"own": 2, "sensing": {"radius_m": 3.0, "report_tracks": False}}


@pytest.mark.parametrize("radius", [0.0, -1.0, float("nan"), -float("inf"), True, "3"])
def test_a_radius_that_is_no_distance_is_refused(radius):
    with pytest.raises(PipelineError, match="sensor radius must be a finite number of metres > 0"):
        RangeLimited(Keep(), radius)


@pytest.mark.parametrize(
    "inner, message",
    [
        (ControllerSpec("cmpc"), "RangeLimited takes a controller built by make_controller(spec), not the"),
        ("cmpc", "RangeLimited: 'cmpc' is no controller: it has no reset, act, describe, close, name"),
    ],
)
def test_a_spec_or_a_name_in_place_of_a_controller_is_one_line(inner, message):
    # each failed on inner.name: AttributeError: 'ControllerSpec' object has no attribute 'name'
    with pytest.raises(PipelineError, match=re.escape(message)):
        RangeLimited(inner, 3.0)


def test_report_tracks_must_be_a_bool():
    with pytest.raises(PipelineError, match="report_tracks must be True or False, got 'no'"):
        RangeLimited(Keep(), 3.0, report_tracks="no")


def test_an_mpc_runs_a_whole_episode_through_the_sensor():
    controller = make_controller(ControllerSpec("cmpc", "social_lstm_eth"))
    controller.prepare(3, range(0, 4))
    result = run_episode(RangeLimited(controller, 2.0), seed=0, scenario="circle", n_humans=3)
    assert result.metrics.n_steps > 10 and result.controller == "cmpc"
    assert result.human_positions.shape[1] == 3  # the metrics are the simulator's, over every human


def test_the_loop_refuses_a_wrapped_controller_built_for_another_world():
    from crowdsim.env_config import EnvConfig

    sensor = RangeLimited(make_controller(ControllerSpec("orca")), 3.0)
    slow = EnvConfig(v_max=0.5)
    with pytest.raises(PipelineError, match="built for another world"):
        run_episode(sensor, seed=0, scenario="circle", n_humans=3, env_config=slow)


class NoOutput(Keep):
    def act(self, obs):
        return np.zeros((obs.n_robots, 2))  # bare accelerations


class ListDescribed(Keep):
    def describe(self):
        return ["not", "a", "dict"]


class Raises(Keep):
    def act(self, obs):
        raise ValueError("boom")


@pytest.mark.parametrize(
    "plugin, message",
    [
        (NoOutput, r"\(NoOutput\): act\(\) must return a crowdsim.control.ControlOutput, got numpy.ndarray"),
        (ListDescribed, r"\(ListDescribed\): describe\(\) must return a dict, got list"),
        (Raises, r"\(Raises\): act\(\) raised ValueError: boom"),
    ],
)
def test_a_wrapped_plugin_that_breaks_the_contract_is_told_as_unwrapped(plugin, message):
    # behind the sensor it read "(RangeLimited): act() raised AttributeError: 'numpy.ndarray' object has no
    # attribute 'extra'" and "describe() raised TypeError: 'list' object is not a mapping"
    with pytest.raises(PipelineError, match=message):
        run_episode(RangeLimited(plugin(), 3.0), seed=0, scenario="circle", n_humans=2)


def test_a_shipped_controllers_exception_behind_the_sensor_is_a_bug_with_its_traceback(monkeypatch):
    # it became "controller 'orca' (RangeLimited): act() raised TypeError: ..." as a plugin's error, which
    # run_episodes turned into a one-line EpisodeFailed without the traceback
    from crowdsim.baselines import OrcaController

    def bug(self, *args, **kwargs):
        raise TypeError("a bug in a shipped controller")

    monkeypatch.setattr(OrcaController, "act", bug)
    sensor = RangeLimited(make_controller(ControllerSpec("orca")), 3.0)
    with pytest.raises(TypeError, match="a bug in a shipped controller"):
        run_episode(sensor, seed=0, scenario="circle", n_humans=2)


@pytest.mark.parametrize("tracks", [False, "no"])
def test_run_episodes_refuses_track_settings_without_a_sensor(tracks):
    # the episodes ran with every human seen, without a word, where simulate refuses --no-sensor-tracks alone
    from pipelines.loop.episode import run_episodes

    with pytest.raises(PipelineError, match="sensor_tracks=.* is a sensor's setting; give sensor_range too"):
        run_episodes(ControllerSpec("straight"), episodes=1, seed=0, scenario="circle", n_humans=2,
                     progress=False, sensor_tracks=tracks)  # fmt: skip


def test_calibrations_scorer_classes_people_behind_a_sensor_as_the_controller_did():
    """A person come into view at step 10 is "new" to the controller (a track of one position); the scorer
    classed it by the simulator's observation, seen since the episode began, as slow. The one in view
    throughout (9 positions tracked, a full window of 8) is slow to both: 0.1 m a step is 0.25 m/s."""
    from types import SimpleNamespace

    from pipelines.experiments.calibrate import PredictionErrors
    from pipelines.loop.motion_classes import observed_classes

    sensor = RangeLimited(Predicting(), radius=3.0)
    before, now = observation(9, [[1.0, 0.0], [5.0, 0.0]], 8), observation(10, [[1.1, 0.0], [2.5, 0.0]], 8)
    sensor.reset(before)
    observer = PredictionErrors(near=3.0)
    observer.on_reset(now, {})
    out = sensor.act(now)
    assert out.extra["tracked"] == [9, 1] and sensor.inner.seen.human_observed.tolist() == [9, 1]
    assert observed_classes(sensor.inner.seen).tolist() == [2, 0]  # the controller's
    assert observed_classes(now).tolist() == [2, 2]  # the simulator's observation
    observer.on_step(now, out, now)
    truth = np.broadcast_to(now.human_positions, (13, 2, 2))
    observer.on_end(
        SimpleNamespace(human_positions=truth, robot_positions=np.zeros((13, 1, 2)), human_present=None)
    )
    assert observer.classes.tolist() == [2, 0]
    np.testing.assert_allclose(observer.errors, np.zeros((2, 2)))  # it predicts them to stay: they do


def test_a_numpy_range_is_a_range():
    """np.int64(3) was refused as "a finite number of metres > 0"."""
    sensed = RangeLimited(make_controller(ControllerSpec("straight")), np.int64(3))
    assert sensed.radius == 3.0 and type(sensed.radius) is float
    with pytest.raises(PipelineError, match="sensor radius must be a finite number of metres > 0, got True"):
        RangeLimited(make_controller(ControllerSpec("straight")), np.True_)
