"""Prediction metrics as TrajNet++ defines them (Kothari et al. 2021; trajnetplusplusbaselines' evaluator).

* ADE: mean L2 distance between the primary pedestrian's predicted and true positions over the predicted
  steps; FDE: the distance at the last step. Both in metres, averaged over scenes.
* Col-I (prediction collision): the primary's prediction collides with the *predicted* path of a neighbour.
  Counted only where the model predicted exactly the neighbours the ground truth has (after dropping those
  that appear only after the observation). Percent of those scenes; the TrajNet++ evaluator instead reports
  Col-I as -1 for the whole file when any scene's neighbours differ (every scene of the ETH test split
  matches, so the two agree there).
* Col-II (ground-truth collision): the primary's prediction collides with a neighbour's *true* path, of the
  neighbours seen at some observed step (TrajNet++ drops later arrivals here too). Percent of scenes.
* A collision is ``trajnetplusplustools.metrics.collision``: over the common frames, consecutive steps are
  joined by segments sampled at their ends and midpoints, and two pedestrians of radius 0.1 m touch at
  some sample (``collides`` hands the library only the pairs that come that close). A neighbour's NaN row
  is a frame it is absent from, as in ``Reader.paths_to_xy`` (the scenes are read so), and its path is
  joined across it; TrajNet++'s evaluator, reading paths, keeps the row as a common frame whose segments
  never collide (a comparison with NaN is false), so on a file with NaN rows its Col-II can be lower. The
  TrajNet++ files here have none.
* Top-k ADE/FDE (k samples): ADE of the sample with the lowest ADE, and that sample's FDE
  (``trajnetplusplustools.metrics.topk``). TrajNet++'s evaluator ranks prediction numbers 0-2 (its table's
  "Top3"), prediction 0 among them, which its ADE and collisions score; here the k samples are drawn apart
  from the scored prediction (a GAN's zero-noise one).

Predictions are rounded to centimetres before scoring, as the TrajNet++ evaluator's writer does (Python's
``round``: ``round_cm``). ``ade``/``fde`` are plain vectorised versions (numpy or torch) for training losses
and logging.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np
from trajnetplusplustools import TrackRow
from trajnetplusplustools import metrics as tt_metrics


def ade(pred, truth):
    """Mean displacement over steps, ``(..., H, 2)`` -> ``(...)``; numpy arrays or torch tensors."""
    return (((pred - truth) ** 2).sum(-1) ** 0.5).mean(-1)


def fde(pred, truth):
    """Final displacement: ``(..., H, 2)`` -> ``(...)``; numpy arrays or torch tensors."""
    return ((pred[..., -1, :] - truth[..., -1, :]) ** 2).sum(-1) ** 0.5


PERSON_RADIUS: Final[float] = 0.1  # m, trajnetplusplustools.metrics.collision default
# Slack for the exact prefilter below: a pair is handed to trajnetplusplustools unless it is clearly apart.
_PREFILTER_SLACK: Final[float] = 1e-6


def collides(primary: np.ndarray, other: np.ndarray, frames: np.ndarray, pedestrian: int = 1) -> bool:
    """``trajnetplusplustools.metrics.collision`` of two ``(H, 2)`` paths over the same ``frames`` (NaN =
    absent in ``other``; ``primary`` complete).

    The library's check walks the common steps in Python; most pairs are metres apart, so a vectorised pass
    over the very points it samples (each step and each segment midpoint, as offsets between the two paths)
    rules those out first, and only the pairs that come within reach are decided by the library itself.
    """
    present = ~np.isnan(other).any(axis=-1)
    if present.sum() < 2:  # the library pairs consecutive common steps; fewer than two give no segment
        return False
    gap = primary[present] - other[present]
    points = np.concatenate([gap, 0.5 * (gap[:-1] + gap[1:])])
    if np.hypot(points[:, 0], points[:, 1]).min() > 2 * PERSON_RADIUS + _PREFILTER_SLACK:
        return False
    return bool(
        tt_metrics.collision(
            track_rows(primary, frames), track_rows(other, frames, pedestrian), n_predictions=len(frames)
        )
    )


def track_rows(
    xy: np.ndarray, frames: np.ndarray, pedestrian: int = 0, prediction_number=None
) -> list[TrackRow]:
    """``(T, 2)`` positions at ``frames`` as trajnetplusplustools rows, absent steps omitted."""
    return [
        TrackRow(int(f), pedestrian, float(x), float(y), prediction_number)
        for f, (x, y) in zip(frames, xy, strict=True)
        if not (np.isnan(x) or np.isnan(y))
    ]


# How near half a centimetre (in centimetres) a value must lie for np.round and round to possibly disagree:
# np.round's product by 100 errs by at most ~1e-9 cm below 10^5 m (the data's bound), far inside this.
_TIE_REACH: Final[float] = 1e-6


def round_cm(values: np.ndarray) -> np.ndarray:
    """``values`` rounded to centimetres as Python's ``round(v, 2)`` rounds them, which is what the TrajNet++
    evaluator's writer (``trajnetplusplustools.writers.trajnet``) applies to predictions.

    ``round`` decides from the exact binary value; ``np.round`` scales by 100 first, so near half a
    centimetre the two part: 0.015 (stored as 0.01499...) is 0.01 to ``round`` but 0.02 to ``np.round``, and
    a predictor whose positions fall on half centimetres scored up to 0.005 m per coordinate off. Only those
    near ties are handed to ``round``.
    """
    values = np.asarray(values, dtype=float)
    rounded = np.round(values, 2)
    scaled = np.abs(values * 100.0)
    near_tie = np.abs(scaled - np.floor(scaled) - 0.5) < _TIE_REACH
    rounded[near_tie] = [round(float(v), 2) for v in values[near_tie]]
    return rounded


@dataclass(frozen=True)
class SceneScore:
    ade: float  # m
    fde: float  # m
    col_i: bool | None  # None: the predicted neighbours are not the ground truth's, so Col-I does not apply
    col_ii: bool
    topk_ade: float | None = None  # m, with samples only
    topk_fde: float | None = None


def score_scene(
    prediction: np.ndarray,
    predicted_agents: Sequence[int],
    truth: np.ndarray,
    frames: np.ndarray,
    obs_len: int,
    samples: np.ndarray | None = None,
) -> SceneScore:
    """TrajNet++ metrics of one scene.

    ``prediction``: ``(H, N_h, 2)`` predicted positions of ``predicted_agents`` (indices into the scene's
    agents, the primary -- agent 0 -- first); ``truth``: ``(obs_len + H, N, 2)`` true positions, NaN where
    absent; ``frames``: ``(obs_len + H,)`` frame ids; ``samples``: optional ``(k, H, N_h, 2)`` for top-k.
    """
    horizon = truth.shape[0] - obs_len
    if prediction.shape[0] != horizon or list(predicted_agents)[:1] != [0]:
        raise ValueError(
            f"prediction must be ({horizon}, N_h, 2) with the primary (agent 0) first, got "
            f"{prediction.shape} for agents {list(predicted_agents)}"
        )
    future = frames[obs_len:]
    prediction = round_cm(prediction)
    truth_primary = track_rows(truth[obs_len:, 0], future)
    if len(truth_primary) != horizon:
        absent = [int(f) for f, xy in zip(future, truth[obs_len:, 0], strict=True) if np.isnan(xy).any()]
        raise ValueError(
            "the primary pedestrian (agent 0) must be present at every predicted step; it is absent at "
            f"frame {absent[0]} ({len(absent)} of {horizon} predicted frames: {absent})"
        )
    primary = track_rows(prediction[:, 0], future)
    ade_value = tt_metrics.average_l2(truth_primary, primary, n_predictions=horizon)
    fde_value = tt_metrics.final_l2(truth_primary, primary)

    # neighbours that exist for the evaluator: present at some observed step
    neighbours = [j for j in range(1, truth.shape[1]) if not np.isnan(truth[:obs_len, j]).any(axis=-1).all()]
    # the library intersects frames; only the predicted ones can be common with the primary's prediction
    col_ii = any(collides(prediction[:, 0], truth[obs_len:, j], future, j) for j in neighbours)
    col_i = None
    if sorted(predicted_agents[1:]) == neighbours:
        col_i = any(
            collides(prediction[:, 0], prediction[:, k], future, int(j))
            for k, j in enumerate(predicted_agents[1:], start=1)
        )

    topk_ade = topk_fde = None
    if samples is not None:
        samples = round_cm(samples)
        rows = [r for m in range(samples.shape[0]) for r in track_rows(samples[m, :, 0], future, 0, m)]
        topk_ade, topk_fde = tt_metrics.topk(
            rows, truth_primary, n_predictions=horizon, k_samples=samples.shape[0]
        )
    return SceneScore(
        float(ade_value),
        float(fde_value),
        col_i,
        bool(col_ii),
        None if topk_ade is None else float(topk_ade),
        None if topk_fde is None else float(topk_fde),
    )


def summarize(scores: Sequence[SceneScore]) -> dict:
    """Scene-averaged metrics: ``scenes``, ``ade``, ``fde`` (m), ``col_i``, ``col_ii`` (%), ``col_i_scenes``
    (scenes Col-I applies to), and ``topk_ade``/``topk_fde`` when every scene has them."""
    n = len(scores)
    if n == 0:
        return {"scenes": 0}
    col_i = [s.col_i for s in scores if s.col_i is not None]
    result = {
        "scenes": n,
        "ade": float(np.mean([s.ade for s in scores])),
        "fde": float(np.mean([s.fde for s in scores])),
        "col_i": 100.0 * float(np.mean(col_i)) if col_i else None,
        "col_i_scenes": len(col_i),
        "col_ii": 100.0 * float(np.mean([s.col_ii for s in scores])),
    }
    if all(s.topk_ade is not None for s in scores):
        result["topk_ade"] = float(np.mean([s.topk_ade for s in scores]))
        result["topk_fde"] = float(np.mean([s.topk_fde for s in scores]))
    return result
