import json

import numpy as np
import pytest

from predictors.constant_velocity import ConstantVelocity
from predictors.errors import PredictorError
from predictors.evaluate import EvalConfig, evaluate, format_table, load_eval_scenes
from tests.predictors.samples import STEP, scene, track, write_lines, write_walk_file


def stopping_file(path):
    """Primary walks +x at 0.5 m/step for 9 steps, then stands at x = 4 for the 12 predicted steps."""
    records = [scene(0, 1, 0, 20 * STEP)]
    for k in range(21):
        records.append(track(k * STEP, 1, 0.5 * min(k, 8), 0.0))
        records.append(track(k * STEP, 2, 0.0, 10.0))
    return write_lines(path, records)


def test_constant_velocity_is_exact_on_straight_walks(tmp_path):
    path = write_walk_file(tmp_path / "walk.ndjson")
    result = evaluate(ConstantVelocity(), [path], progress=False, root=tmp_path)
    metrics = result["files"]["walk.ndjson"]
    assert metrics["scenes"] == 2
    assert metrics["ade"] == pytest.approx(0.0) and metrics["fde"] == pytest.approx(0.0)
    assert metrics["col_i"] == 0.0 and metrics["col_ii"] == 0.0  # the walkers stay 1 m apart
    json.dumps(result)  # JSON-ready


def test_constant_velocity_overshoots_a_stop(tmp_path):
    path = stopping_file(tmp_path / "stop.ndjson")
    result = evaluate(ConstantVelocity(), [path], progress=False)
    overall = result["overall"]
    # errors 0.5 h m for h = 1..12: mean 0.5 x 6.5, final 6
    assert overall["ade"] == pytest.approx(3.25) and overall["fde"] == pytest.approx(6.0)
    table = format_table(result)
    assert "3.250" in table and "6.000" in table


def test_pooled_overall_over_files(tmp_path):
    files = [write_walk_file(tmp_path / "walk.ndjson"), stopping_file(tmp_path / "stop.ndjson")]
    result = evaluate(ConstantVelocity(), files, progress=False)
    assert result["overall"]["scenes"] == 3
    assert result["overall"]["ade"] == pytest.approx(3.25 / 3)
    assert "overall" in format_table(result)


def test_observation_only_files_are_refused(tmp_path):
    records = [scene(0, 1, 0, 8 * STEP)] + [track(k * STEP, 1, 0.5 * k, 0.0) for k in range(9)]
    path = write_lines(tmp_path / "test_only.ndjson", records)
    with pytest.raises(
        PredictorError, match=r"test_only.ndjson:1: scene 0 has 9 steps, the evaluation needs 21"
    ):
        load_eval_scenes(path)


class Sampler(ConstantVelocity):
    name = "sampler"

    def sample(self, history, mask, robots_future, humans, horizon, k, rng):
        base = self.rollout(history, mask, robots_future, humans, horizon)
        return np.stack([base + [0.0, float(i)] for i in range(k)])


def test_top_k_for_predictors_that_sample(tmp_path):
    path = stopping_file(tmp_path / "stop.ndjson")
    result = evaluate(Sampler(), [path], EvalConfig(top_k=3), progress=False)
    assert result["top_k"] == 3
    assert result["overall"]["topk_ade"] == pytest.approx(3.25)  # the unshifted sample is the best
    assert "top-3 ADE" in format_table(result)
    assert evaluate(ConstantVelocity(), [path], EvalConfig(top_k=3), progress=False)["top_k"] is None
    with pytest.raises(PredictorError, match="top-k"):
        EvalConfig(top_k=0)


def test_a_predictor_reading_more_steps_than_the_protocol_gives_is_refused_first(tmp_path):
    """A zoo net trained to read 10 steps (obs_len up to 100 is allowed) failed inside the first scene with
    the predictor API's words ("pad a short track ..."), which a command-line user cannot act on."""
    path = write_walk_file(tmp_path / "walk.ndjson")
    with pytest.raises(
        PredictorError, match=r"reads 10 observed steps, the evaluation gives 9 of each scene"
    ):
        evaluate(ConstantVelocity(obs_len=10), [path])


class Diverging(Sampler):
    """Constant velocity whose primary's forecast (or one neighbour's sample) turns NaN at step 3."""

    name = "diverging"

    def __init__(self, agent: int = 0, in_samples: bool = False):
        super().__init__()
        self.agent, self.in_samples = agent, in_samples

    def rollout(self, history, mask, robots_future, humans, horizon=None):
        future = super().rollout(history, mask, robots_future, humans, horizon)
        if not self.in_samples:
            future[2, self.agent] = np.nan
        return future

    def sample(self, history, mask, robots_future, humans, horizon, k, rng):
        samples = super().sample(history, mask, robots_future, humans, horizon, k, rng)
        samples[1, 2, self.agent, 0] = np.inf
        return samples


def test_a_non_finite_prediction_is_refused_naming_where(tmp_path):
    """A NaN primary ended in trajnetplusplustools' bare AssertionError; a NaN neighbour was scored as absent
    (its segments joined across the gap), where TrajNet++'s evaluator reads a present row colliding with
    nothing. Either is the predictor's fault, said in one line."""
    path = write_walk_file(tmp_path / "walk.ndjson")
    with pytest.raises(
        PredictorError,
        match=r"^predictor 'diverging' returned a non-finite position \[nan, nan\] in its prediction "
        r"\(predicted step 3, agent 0\); a predictor must return finite positions$",
    ):
        evaluate(Diverging(), [path], progress=False)
    with pytest.raises(PredictorError, match=r"\[nan, nan\] in its prediction \(predicted step 3, agent 1\)"):
        evaluate(Diverging(agent=1), [path], progress=False)
    with pytest.raises(PredictorError, match=r"\[inf, 1.0\] in its samples \(sample 1, predicted step 3"):
        evaluate(Diverging(in_samples=True), [path], EvalConfig(top_k=3), progress=False)
