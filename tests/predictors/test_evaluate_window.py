"""`crowdmpc evaluate` of a trained model that reads fewer observed steps than a scene's 9 (a zoo entry whose
config says obs_len 3): it is given the last 3 of them and the agents seen there, as TrajNet++'s baselines
give a model ``xy[start_length:obs_length]``, and scored on the scene's own observation."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from predictors.constant_velocity import ConstantVelocity
from predictors.evaluate import evaluate, format_table, handed_steps
from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig
from predictors.social_lstm_predictors import SocialLSTMPredictor
from tests.predictors.samples import STEP, scene, track, write_lines


def net() -> SocialLSTM:
    torch.manual_seed(3)
    return SocialLSTM(SocialLSTMConfig(pooling="grid"))


class WindowedVelocity(SocialLSTMPredictor):
    """A trained model's window (``_prepare``: the last ``obs_len`` rows, an agent unseen in them refused)
    with constant-velocity arithmetic, for numbers a reader can check."""

    def rollout(self, history, mask, robots_future, humans, horizon=None):
        pos, _, n_humans = self._prepare(history, mask, humans, keep_robots=robots_future is not None)
        velocity = pos[-1, :n_humans] - pos[-2, :n_humans]
        return pos[-1, :n_humans] + np.arange(1, horizon + 1)[:, None, None] * velocity


def leaving_file(path):
    """Scene 0: primary 1 walks +x at 0.5 m a step to x = 4 (step 8), then stands there; pedestrian 2 walks
    beside it at y = 10; pedestrian 3 stands at (20, 20) in steps 0-4, is unseen in steps 5-8 and stands at
    (6, 0), on the primary's straight line, from step 9. Scene 1 (frames 1000-1200): primary 4 and
    pedestrian 5 walk +x 1 m apart, seen throughout."""
    records = [scene(0, 1, 0, 20 * STEP), scene(1, 4, 1000, 1000 + 20 * STEP)]
    for k in range(21):
        records.append(track(k * STEP, 1, 0.5 * min(k, 8), 0.0))
        records.append(track(k * STEP, 2, 0.5 * k, 10.0))
        if k <= 4 or k >= 9:
            records.append(track(k * STEP, 3, 20.0 if k <= 4 else 6.0, 20.0 if k <= 4 else 0.0))
        records.append(track(1000 + k * STEP, 4, 0.5 * k, 0.0))
        records.append(track(1000 + k * STEP, 5, 0.5 * k, 1.0))
    return write_lines(path, records)


def test_a_three_step_model_is_scored_on_the_scenes_observation(tmp_path):
    path = leaving_file(tmp_path / "leaving.ndjson")
    result = evaluate(WindowedVelocity(net(), name="windowed", obs_len=3), [path], progress=False)
    overall = result["overall"]
    assert result["obs_len"] == 9 and result["steps_given"] == 3
    # scene 0: the forecast walks on at 0.5 m a step from x = 4 where the primary stands: errors 0.5 h m,
    # h = 1..12 (mean 3.25, final 6); scene 1 is exact
    assert overall["scenes"] == 2
    assert overall["ade"] == pytest.approx(3.25 / 2) and overall["fde"] == pytest.approx(6.0 / 2)
    # Col-II: pedestrian 3, seen in the observation though not in the model's 3 steps, stands at (6, 0),
    # which the forecast reaches at h = 4
    assert overall["col_ii"] == pytest.approx(50.0)
    # Col-I: scene 0's predicted neighbours (2) are not its observed ones (2, 3): only scene 1 counts, 0 %
    assert overall["col_i_scenes"] == 1 and overall["col_i"] == 0.0
    table = format_table(result)
    assert "windowed: the last 3 of 9 observed -> 12 predicted steps" in table
    assert "0.00*" in table and "50.00" in table
    assert "* Col-I of 1 of 2 scenes: those whose every neighbour seen in the 9 observed steps" in table


def test_a_trained_network_reading_three_steps_is_scored(tmp_path):
    """It stopped at scene 0: "agents [2] are never observed in the last 3 steps of the history"."""
    path = leaving_file(tmp_path / "leaving.ndjson")
    result = evaluate(SocialLSTMPredictor(net(), name="sl3", obs_len=3), [path], progress=False)
    overall = result["overall"]
    assert overall["scenes"] == 2 and overall["col_i_scenes"] == 1
    assert np.isfinite([overall["ade"], overall["fde"], overall["col_ii"]]).all()


def test_every_other_predictor_keeps_the_whole_observation(tmp_path):
    """Constant velocity (obs_len 2) reads every step it is given and predicts pedestrian 3 standing at
    (20, 20): its scores, and a nine-step model's, are what they were."""
    path = leaving_file(tmp_path / "leaving.ndjson")
    assert handed_steps(ConstantVelocity(), 9) == 9
    assert handed_steps(SocialLSTMPredictor(net(), name="sl", obs_len=9), 9) == 9
    assert handed_steps(SocialLSTMPredictor(net(), name="sl3", obs_len=3), 9) == 3
    result = evaluate(ConstantVelocity(), [path], progress=False)
    overall = result["overall"]
    assert result["steps_given"] == 9 and overall["col_i_scenes"] == 2
    assert overall["ade"] == pytest.approx(3.25 / 2) and overall["col_ii"] == pytest.approx(50.0)
    table = format_table(result)
    assert "constant_velocity: 9 observed -> 12" in table and "*" not in table
