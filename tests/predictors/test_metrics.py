import json

import numpy as np
import pytest
import torch
from trajnetplusplustools import TrackRow, writers
from trajnetplusplustools import metrics as tt_metrics

from predictors.metrics import SceneScore, ade, collides, fde, round_cm, score_scene, summarize, track_rows


def test_ade_fde_hand_computed_numpy_and_torch():
    pred = np.array([[0.0, 0.0], [3.0, 4.0]])
    truth = np.zeros((2, 2))
    assert ade(pred, truth) == pytest.approx(2.5)  # distances 0 and 5
    assert fde(pred, truth) == pytest.approx(5.0)
    batch = torch.tensor(np.stack([pred, pred + [0.0, 1.0]]))
    torch.testing.assert_close(
        ade(batch, torch.zeros_like(batch)), torch.tensor([2.5, (1 + np.hypot(3, 5)) / 2]).double()
    )
    torch.testing.assert_close(
        fde(batch, torch.zeros_like(batch)), torch.tensor([5.0, np.hypot(3, 5)]).double()
    )


def line(start, step, n=12):
    return np.asarray(start, dtype=float) + np.arange(1, n + 1)[:, None] * np.asarray(step, dtype=float)


FRAMES = np.arange(90, 210, 10)


def test_collision_hand_computed():
    primary = line([0.0, 0.0], [0.1, 0.0])  # x = 0.1 .. 1.2 on the x axis
    assert collides(primary, np.tile([0.6, 0.15], (12, 1)), FRAMES)  # 0.15 m <= 2 x 0.1 m
    assert not collides(primary, np.tile([0.6, 0.25], (12, 1)), FRAMES)
    only_one_common = np.full((12, 2), np.nan)
    only_one_common[5] = [0.6, 0.0]
    assert not collides(primary, only_one_common, FRAMES)  # no segment to test, as in TrajNet++


def test_collides_agrees_with_trajnetplusplustools_on_random_pairs():
    rng = np.random.default_rng(0)
    hits = 0
    for _ in range(400):
        primary = np.cumsum(rng.normal(0, 0.15, (12, 2)), axis=0)
        other = primary + rng.normal(0, 0.4, (12, 2)) + rng.normal(0, 0.3, 2)
        other[rng.random(12) < 0.2] = np.nan
        expected = tt_metrics.collision(
            track_rows(primary, FRAMES), track_rows(other, FRAMES, 1), n_predictions=12
        )
        assert collides(primary, other, FRAMES) == expected
        hits += expected
    assert 50 < hits < 350  # both outcomes were exercised


def walking_truth():
    """Primary walks +x at 0.5 m/step for 21 steps; neighbour 1 walks beside it at y = 0.35;
    neighbour 2 appears only after the observation."""
    truth = np.full((21, 3, 2), np.nan)
    x = 0.5 * np.arange(21)
    truth[:, 0] = np.stack([x, np.zeros(21)], axis=1)
    truth[:, 1] = np.stack([x, np.full(21, 0.35)], axis=1)
    truth[12:, 2] = [[20.0, 20.0]] * 9
    return truth


def test_scene_scores_hand_computed():
    truth = walking_truth()
    frames = np.arange(0, 210, 10)
    prediction = np.stack([truth[9:, 0] + [0.0, 0.3], truth[9:, 1] + [0.0, 5.0]], axis=1)  # (12, 2, 2)
    score = score_scene(prediction, [0, 1], truth, frames, obs_len=9)
    assert score.ade == pytest.approx(0.3) and score.fde == pytest.approx(0.3)
    assert score.col_ii  # 0.05 m from neighbour 1's true path
    assert score.col_i is False  # its predicted path is 5 m away
    assert (
        score_scene(prediction[:, :1], [0], truth, frames, obs_len=9).col_i is None
    )  # neighbour unpredicted


def test_a_primary_missing_from_the_truth_is_refused_naming_the_frames():
    truth = walking_truth()
    truth[[13, 17, 18], 0] = np.nan  # predicted steps 4, 8 and 9: frames 130, 170, 180
    frames = np.arange(0, 210, 10)
    with pytest.raises(ValueError) as refused:
        score_scene(truth[9:, :1], [0], truth, frames, obs_len=9)
    assert str(refused.value) == (
        "the primary pedestrian (agent 0) must be present at every predicted step; it is absent at frame "
        "130 (3 of 12 predicted frames: [130, 170, 180])"
    )


def test_top_k_takes_the_best_sample():
    truth = walking_truth()
    frames = np.arange(0, 210, 10)
    prediction = truth[9:, :2]
    samples = np.stack([prediction + [1.0, 0.0], prediction + [0.0, 0.5]])
    score = score_scene(prediction, [0, 1], truth, frames, obs_len=9, samples=samples)
    assert score.topk_ade == pytest.approx(0.5) and score.topk_fde == pytest.approx(0.5)


def test_summarize_averages_scenes_and_gives_percentages():
    scores = [
        SceneScore(1.0, 2.0, True, True),
        SceneScore(2.0, 3.0, False, False),
        SceneScore(3.0, 4.0, None, False),
    ]
    summary = summarize(scores)
    assert (
        summary["scenes"] == 3
        and summary["ade"] == pytest.approx(2.0)
        and summary["fde"] == pytest.approx(3.0)
    )
    assert summary["col_i"] == pytest.approx(50.0) and summary["col_i_scenes"] == 2
    assert summary["col_ii"] == pytest.approx(100 / 3)
    assert "topk_ade" not in summary
    assert summarize([]) == {"scenes": 0}


def test_vectorised_fde_compares_the_last_steps():
    # Truth moves: the last step's truth is (0, 0), the one before (9, 9); FDE = |(3, 4) - (0, 0)| = 5.
    pred = np.array([[0.0, 0.0], [3.0, 4.0]])
    truth = np.array([[9.0, 9.0], [0.0, 0.0]])
    assert fde(pred, truth) == pytest.approx(5.0)


def two_neighbours_truth():
    """Primary walks +x at 0.5 m/step; neighbour 1 walks 5 m beside it, neighbour 2 0.15 m beside it (within
    2 x 0.1 m: touching)."""
    truth = np.zeros((21, 3, 2))
    truth[:, :, 0] = 0.5 * np.arange(21)[:, None]
    truth[:, 1, 1], truth[:, 2, 1] = 5.0, 0.15
    return truth


def test_collisions_check_every_neighbour_against_its_own_path():
    """Col-II: the true path of neighbour 2 (the second) touches the primary's prediction. Col-I: the
    *predicted* path of neighbour 1 (column 1) touches it, neighbour 2's prediction is 5 m away."""
    truth, frames = two_neighbours_truth(), np.arange(0, 210, 10)
    prediction = truth[9:].copy()
    prediction[:, 1, 1], prediction[:, 2, 1] = -0.15, -5.0
    score = score_scene(prediction, [0, 1, 2], truth, frames, obs_len=9)
    assert score.col_ii is True and score.col_i is True
    # Only the other neighbour's prediction near the primary: no Col-I.
    prediction[:, 1, 1], prediction[:, 2, 1] = 5.0, -5.0
    assert score_scene(prediction, [0, 1, 2], truth, frames, obs_len=9).col_i is False
    # Predicting neighbour 1 only, while the truth has 1 and 2: Col-I does not apply.
    assert score_scene(prediction[:, :2], [0, 1], truth, frames, obs_len=9).col_i is None


def test_predictions_and_samples_are_rounded_to_centimetres():
    """As the TrajNet++ evaluator does: 4 mm off rounds to the exact truth (the truth is on a 0.5 m grid)."""
    truth, frames = walking_truth(), np.arange(0, 210, 10)
    prediction = truth[9:, :2] + [0.004, -0.004]
    score = score_scene(prediction, [0, 1], truth, frames, obs_len=9, samples=prediction[None])
    assert score.ade == 0.0 and score.fde == 0.0
    assert score.topk_ade == 0.0 and score.topk_fde == 0.0


def test_summarize_gives_top_k_only_when_every_scene_has_it():
    with_k = [SceneScore(1.0, 2.0, None, False, 0.5, 1.0), SceneScore(2.0, 3.0, None, False, 1.5, 2.0)]
    summary = summarize(with_k)
    assert summary["topk_ade"] == pytest.approx(1.0) and summary["topk_fde"] == pytest.approx(1.5)
    assert "topk_ade" not in summarize([*with_k, SceneScore(3.0, 4.0, None, False)])


def test_a_neighbour_that_appears_only_after_the_observation_is_not_scored():
    """TrajNet++ drops neighbours absent from every observed step: neighbour 2 walks right beside the primary
    (0.1 m) from the first predicted step on, yet is no Col-II collision; neighbour 1 is 0.35 m away."""
    truth = walking_truth()
    truth[9:, 2] = truth[9:, 0] + [0.0, 0.1]
    score = score_scene(truth[9:, :1], [0], truth, np.arange(0, 210, 10), obs_len=9)
    assert score.col_ii is False


def test_a_prediction_without_the_primary_first_is_refused():
    """The predicted agents must start with the primary (agent 0), whose row the scores are of."""
    truth = walking_truth()
    frames = np.arange(0, 210, 10)
    with pytest.raises(ValueError, match=r"primary \(agent 0\) first, got \(12, 2, 2\) for agents \[1, 0\]"):
        score_scene(truth[9:, [1, 0]], [1, 0], truth, frames, obs_len=9)


def test_two_pedestrians_exactly_two_radii_apart_collide():
    """TrajNet++ counts a distance equal to 2 x 0.1 m as a collision (<=): a neighbour standing 0.2 m
    beside the primary's path (at x = 0.6, y = 0.2) collides; the exact prefilter must not rule it out."""
    primary = line([0.0, 0.0], [0.1, 0.0])
    beside = np.tile([0.6, 0.2], (12, 1))
    assert tt_metrics.collision(track_rows(primary, FRAMES), track_rows(beside, FRAMES, 1), n_predictions=12)
    assert collides(primary, beside, FRAMES)


def test_predictions_are_rounded_as_the_trajnet_writer_rounds_them():
    """TrajNet++'s evaluator scores the predictions its writer wrote, Python's ``round(v, 2)`` of each
    coordinate. ``np.round`` parts from it at half centimetres: 0.015 (0.01499...) went to 0.02 and 0.005
    (0.00500...01) to 0.0, so a primary standing at the origin predicted at (0.015, 0.005) scored 0.02 m,
    where TrajNet++ scores |(0.01, 0.01)|."""
    truth = np.zeros((21, 1, 2))
    prediction = np.tile([0.015, 0.005], (12, 1, 1))
    score = score_scene(prediction, [0], truth, np.arange(0, 210, 10), obs_len=9, samples=prediction[None])
    assert score.ade == pytest.approx(0.01 * np.sqrt(2)) and score.fde == pytest.approx(0.01 * np.sqrt(2))
    assert score.topk_ade == pytest.approx(0.01 * np.sqrt(2))
    values = np.concatenate([np.arange(-2000, 2000) * 0.01 + 0.005, [0.125, -0.125, 1.2345678, np.nan]])
    written = [json.loads(writers.trajnet(TrackRow(0, 1, float(v), 0.0)))["track"]["x"] for v in values]
    np.testing.assert_array_equal(round_cm(values), np.array(written, dtype=float))


def test_a_nan_row_of_a_neighbour_is_a_frame_it_is_absent_from():
    """The difference from TrajNet++'s evaluator that predictors/metrics.py states: a neighbour crossing the
    primary's prediction at predicted step 6, its row there NaN, collides here (its path joined from step 5
    to 7 meets the primary's midpoint), as it does with no row at all; TrajNet++'s ``collision`` on the rows
    as read, the NaN one kept, finds no collision."""
    primary = line([0.0, 0.0], [0.5, 0.0])  # x = 0.5 .. 6.0, at x = 3.0 on step 6
    crossing = np.stack([np.full(12, 3.0), 0.5 * (np.arange(1, 13) - 6.0)], axis=1)
    crossing[5] = np.nan
    assert collides(primary, crossing, FRAMES)
    with_nan_row = [*track_rows(crossing, FRAMES, 1)]
    with_nan_row.insert(5, TrackRow(int(FRAMES[5]), 1, float("nan"), float("nan")))
    assert not tt_metrics.collision(track_rows(primary, FRAMES), with_nan_row, n_predictions=12)
    assert tt_metrics.collision(
        track_rows(primary, FRAMES), track_rows(crossing, FRAMES, 1), n_predictions=12
    )
