"""TrajNet++ scenes cut from annotated tracks, and the ndjson files that hold them, as TrajNet++'s converter
makes them.

The reference is ``vita-epfl/trajnetplusplusdataset`` (``scene.Scenes``, ``convert.write``,
``get_type.trajectory_type``), reimplemented here on numpy arrays:

1. Chunking: for each pedestrian (in order of first appearance) the frame-sorted rows are cut into windows of
   ``chunk_size`` = 21 rows (9 observed + 12 predicted) starting every ``chunk_stride`` = 2 rows. A window
   becomes a scene of that primary pedestrian if (a) the primary moved: squared displacement first -> last
   above ``min_length`` (0 by default, so only a perfectly still primary fails); (b) it has no gap: the
   largest frame increment is below 1.5 x the (upper) median increment, and here additionally the median is
   the sequence's own ``frame_step``; (c) there is activity: at least 2 x 21 rows (all pedestrians) in its
   frames; (d) the primary is near someone: at one of its frames it shares a 10 m x 10 m grid cell with
   another pedestrian.
2. Categorisation (TrajNet++ types): I static (primary moves < 1 m), II linear (a Kalman filter fitted on
   the 9 observed steps predicts the final position within 0.5 m), III interacting (someone in a 15 deg cone
   within 5 m ahead, or a group), IV other; III gets sub-types 1 leader-follower, 2 collision avoidance,
   3 group, 4 other. The checks are trajnetplusplustools' own (``kalman``, ``interactions``), on coordinates
   rounded to centimetres as the converter's intermediate file has them.
3. Acceptance: a scene of type k is kept with probability ``acceptance[k-1]`` (TrajNet++: 0.1 for static,
   1 otherwise). TrajNet++ draws from numpy's global generator in file order, which cannot be replayed; here
   each scene draws from its own generator seeded by (seed, primary, start frame), so the result is
   deterministic and does not depend on what else is in the file.
4. Writing: scene records first (ids consecutive from ``start_scene_id``), then every row (all pedestrians)
   at a frame of some kept scene's primary, sorted by frame, with coordinates rounded to centimetres by
   ``trajnetplusplustools.writers``.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np
from trajnetplusplustools import Reader, SceneRow, TrackRow, kalman
from trajnetplusplustools import metrics as tt_metrics
from trajnetplusplustools.interactions import check_interaction, get_interaction_type, group
from trajnetplusplustools.writers import trajnet

from crowdsim.world import RECORDED_FPS
from predictors.base import OBS_LEN, PRED_LEN
from predictors.data.validate import rows_by_pedestrian
from predictors.durable import replace_durably
from predictors.progress import progress_bar
from predictors.text_table import counted

# Converter defaults (trajnetplusplusdataset convert.py arguments, scene.py constants).
CHUNK_SIZE: Final[int] = OBS_LEN + PRED_LEN  # 21 rows = 9 observed + 12 predicted
CHUNK_STRIDE: Final[int] = 2  # convert.py --chunk_stride default
MIN_LENGTH: Final[float] = 0.0  # convert.py --min_length default (compared with the *squared* displacement)
GAP_TOLERANCE: Final[float] = 1.5  # scene.py continuous_frames
ACTIVITY_FACTOR: Final[float] = 2.0  # scene.py: rows in the scene's frames >= 2 x chunk_size
PROXIMITY_CELL: Final[float] = 10.0  # m; scene.py close_pedestrians cell_size
# Categorisation thresholds (convert.py "categorizers" defaults).
STATIC_THRESHOLD: Final[float] = 1.0  # m, type I
LINEAR_THRESHOLD: Final[float] = 0.5  # m, type II (Kalman final-position error)
INTER_POS_RANGE: Final[float] = 15.0  # deg, type III cone half-angle
INTER_DIST_THRESH: Final[float] = 5.0  # m, type III cone length
GROUP_DIST_THRESH: Final[float] = 0.8  # m, type IIIc
GROUP_STD_THRESH: Final[float] = 0.2  # m, type IIIc
TRAJNETPP_ACCEPTANCE: Final[tuple[float, float, float, float]] = (
    0.1,
    1.0,
    1.0,
    1.0,
)  # convert.py --acceptance
DEFAULT_SEED: Final[int] = 42  # convert.py seeds numpy with 42

Tag = int | tuple[int, tuple[int, ...]]


@dataclass(frozen=True)
class SceneSpec:
    """One scene record: the primary pedestrian and its first/last frame (inclusive)."""

    id: int
    primary: int
    start_frame: int
    end_frame: int
    fps: float = RECORDED_FPS
    tag: Tag = 0  # (type 1-4, interaction sub-types) when categorised, else 0

    def json_tag(self) -> object:
        return [self.tag[0], list(self.tag[1])] if isinstance(self.tag, tuple) else self.tag


# ------------------------------------------------------------------------------------------------- chunking


def _check_tracks(tracks: np.ndarray) -> np.ndarray:
    tracks = np.asarray(tracks, dtype=np.float64)
    if tracks.ndim != 2 or tracks.shape[1] != 4:
        raise ValueError(f"tracks must have shape (R, 4) [frame, ped_id, x, y], got {tracks.shape}")
    bad = np.flatnonzero(~np.isfinite(tracks).all(axis=1))
    if bad.size:
        raise ValueError(
            f"tracks must be finite: tracks[{bad[0]}] = {tracks[bad[0]].tolist()} [frame, ped_id, x, y] "
            f"({bad.size} of {len(tracks)} rows hold NaN or inf)"
        )
    ids = tracks[:, :2]
    bad = np.flatnonzero((ids != np.round(ids)).any(axis=1))
    if bad.size:
        raise ValueError(
            f"frame and pedestrian ids in tracks must be integers: tracks[{bad[0]}] has frame "
            f"{float(ids[bad[0], 0])!r}, pedestrian {float(ids[bad[0], 1])!r} ({bad.size} of {len(tracks)} "
            "rows)"
        )
    keys = ids.astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    first_of_key = first[inverse.ravel()]  # (R,) the first row with each row's (frame, pedestrian)
    repeats = np.flatnonzero(first_of_key != np.arange(len(keys)))
    if repeats.size:
        row = repeats[0]
        frame, ped = keys[row].tolist()
        held = counted(repeats.size, "duplicate (frame, pedestrian) row")
        raise ValueError(
            f"tracks hold {held}; the first is tracks[{row}]: frame {frame}, pedestrian {ped}, already at "
            f"tracks[{first_of_key[row]}]"
        )
    return tracks


def _continuous(frames: np.ndarray, frame_step: int) -> bool:
    steps = np.diff(frames)
    median = np.sort(steps)[len(steps) // 2]  # the converter's upper median
    return bool(median * GAP_TOLERANCE > steps.max() and median == frame_step)


def _close_rows(frames: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(R,) bool: the row shares its frame's 10 m grid cell with another row (scene.py close_pedestrians)."""
    cells = np.floor_divide(xy, PROXIMITY_CELL).astype(np.int64)
    keys = np.column_stack([frames, cells])
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    return counts[inverse.ravel()] > 1


def _candidate_windows(
    tracks: np.ndarray, frame_step: int, chunk_size: int, chunk_stride: int, min_length: float
) -> list[tuple[int, np.ndarray]]:
    """(primary, row indices of its window) for every window that passes the converter's filters."""
    frames = tracks[:, 0].astype(np.int64)
    peds = tracks[:, 1].astype(np.int64)
    xy = tracks[:, 2:4]
    unique_frames, frame_inverse, frame_counts = np.unique(frames, return_inverse=True, return_counts=True)
    rows_at = frame_counts[frame_inverse.ravel()]  # (R,) rows sharing each row's frame
    close = _close_rows(frames, xy)

    by_ped = rows_by_pedestrian(frames, peds)
    _, first_row = np.unique(peds, return_index=True)
    candidates = []
    for ped in peds[np.sort(first_row)]:  # pedestrians in order of first appearance, like the converter
        rows = by_ped[int(ped)]
        for i in range(0, len(rows) - chunk_size + 1, chunk_stride):
            window = rows[i : i + chunk_size]
            if np.sum((xy[window[0]] - xy[window[-1]]) ** 2) <= min_length:
                continue
            if not _continuous(frames[window], frame_step):
                continue
            if rows_at[window].sum() < ACTIVITY_FACTOR * chunk_size:
                continue
            if not close[window].any():
                continue
            candidates.append((int(ped), window))
    return candidates


# ----------------------------------------------------------------------------------------- categorisation


@contextmanager
def _global_numpy_seed(entropy: Sequence[int]):
    """trajnetplusplustools' Kalman filter samples from numpy's global generator; make that reproducible
    without leaving the global state changed."""
    # the legacy global generator is deliberate here: it is the one pykalman draws from
    state = np.random.get_state()  # noqa: NPY002
    np.random.seed(np.random.SeedSequence([int(v) % 2**63 for v in entropy]).generate_state(4))  # noqa: NPY002
    try:
        yield
    finally:
        np.random.set_state(state)  # noqa: NPY002


def categorize(
    paths: list[list[TrackRow]], *, obs_len: int, pred_len: int, seed: int
) -> tuple[int, tuple[int, ...]]:
    """TrajNet++ type (1-4) and interaction sub-types of one scene given as Reader paths (primary first)."""
    primary = paths[0]
    if np.hypot(primary[0].x - primary[-1].x, primary[0].y - primary[-1].y) < STATIC_THRESHOLD:
        return 1, ()
    with _global_numpy_seed((seed, primary[0].pedestrian, primary[0].frame)):
        prediction, _ = kalman.predict(paths, obs_len, pred_len)[0]
    if tt_metrics.final_l2(primary, prediction) < LINEAR_THRESHOLD:
        return 2, ()
    xy = Reader.paths_to_xy(paths)
    interacting = np.any(
        check_interaction(xy, pos_range=INTER_POS_RANGE, dist_thresh=INTER_DIST_THRESH, obs_len=obs_len)
    ) or np.any(group(xy, GROUP_DIST_THRESH, GROUP_STD_THRESH, obs_len))
    if interacting:
        sub = get_interaction_type(xy, INTER_POS_RANGE, INTER_DIST_THRESH, obs_len)
        return 3, tuple(int(s) for s in sub)
    return 4, ()


def _scene_paths(tracks: np.ndarray, union_frames: np.ndarray, primary: int, start: int, end: int):
    """The scene as the converter's categoriser reads it back: rows at frames of any candidate scene within
    [start, end], coordinates rounded to centimetres as written."""
    frames = tracks[:, 0].astype(np.int64)
    lo, hi = np.searchsorted(union_frames, [start, end + 1])
    rows = np.flatnonzero(np.isin(frames, union_frames[lo:hi]))
    rows = rows[np.argsort(frames[rows], kind="stable")]
    track_rows = [
        TrackRow(
            int(tracks[r, 0]), int(tracks[r, 1]), round(float(tracks[r, 2]), 2), round(float(tracks[r, 3]), 2)
        )
        for r in rows
    ]
    return Reader.track_rows_to_paths(primary, track_rows)


def build_scenes(
    tracks: np.ndarray,
    *,
    frame_step: int,
    chunk_size: int = CHUNK_SIZE,
    chunk_stride: int = CHUNK_STRIDE,
    start_scene_id: int = 0,
    fps: float = RECORDED_FPS,
    obs_len: int = OBS_LEN,
    min_length: float = MIN_LENGTH,
    categorize_scenes: bool = True,
    acceptance: tuple[float, float, float, float] | None = TRAJNETPP_ACCEPTANCE,
    seed: int = DEFAULT_SEED,
    progress: bool | None = False,
) -> list[SceneSpec]:
    """TrajNet++ scenes of ``tracks`` (``(R, 4)`` rows ``frame, ped_id, x, y``), as the converter builds them.

    ``frame_step`` is the frame increment of one time step (10 for hotel, 6 for ETH, 1 for frames numbered by
    step). With ``categorize_scenes`` each scene gets its TrajNet++ tag and ``acceptance`` (per type, None
    keeps all) drops scenes as TrajNet++ does; categorising costs a Kalman fit (~50 ms) per moving primary,
    so for large synthetic sets pass ``categorize_scenes=False`` (tags 0, nothing dropped).
    """
    tracks = _check_tracks(tracks)
    if frame_step < 1 or chunk_size < 2 or chunk_stride < 1:
        raise ValueError(
            f"need frame_step >= 1, chunk_size >= 2, chunk_stride >= 1; got {frame_step}, "
            f"{chunk_size}, {chunk_stride}"
        )
    if categorize_scenes and not 1 <= obs_len < chunk_size:
        raise ValueError(f"obs_len must be in [1, chunk_size) to categorise, got {obs_len}")
    if acceptance is not None and (len(acceptance) != 4 or not all(0 <= a <= 1 for a in acceptance)):
        raise ValueError(f"acceptance must be four probabilities (types I-IV), got {acceptance}")
    if tracks.shape[0] == 0:
        return []
    candidates = _candidate_windows(tracks, frame_step, chunk_size, chunk_stride, min_length)
    frames = tracks[:, 0].astype(np.int64)

    tags: list[Tag] = [0] * len(candidates)
    keep = [True] * len(candidates)
    if categorize_scenes and candidates:
        union_frames = np.unique(np.concatenate([frames[w] for _, w in candidates]))
        iterator: Iterable = enumerate(candidates)
        if progress is not False:  # None: on a terminal only
            iterator = progress_bar(
                iterator, total=len(candidates), desc="categorising", unit="scene", leave=False, show=progress
            )
        for k, (primary, window) in iterator:
            start, end = int(frames[window[0]]), int(frames[window[-1]])
            paths = _scene_paths(tracks, union_frames, primary, start, end)
            kind, sub = categorize(paths, obs_len=obs_len, pred_len=chunk_size - obs_len, seed=seed)
            tags[k] = (kind, sub)
            if acceptance is not None:
                draw = np.random.default_rng([seed % 2**63, primary % 2**63, start % 2**63]).uniform()
                keep[k] = bool(draw < acceptance[kind - 1])

    scenes: list[SceneSpec] = []
    for (primary, window), tag, kept in zip(candidates, tags, keep, strict=True):
        if kept:
            scene_id = start_scene_id + len(scenes)
            start, end = int(frames[window[0]]), int(frames[window[-1]])
            scenes.append(SceneSpec(scene_id, primary, start, end, float(fps), tag))
    return scenes


# --------------------------------------------------------------------------------------------------- writing


def scene_track_rows(scenes: Sequence[SceneSpec], tracks: np.ndarray) -> np.ndarray:
    """Indices of the rows a file of ``scenes`` holds: every row at a frame of some scene's primary,
    sorted by frame (stable)."""
    tracks = _check_tracks(tracks)
    frames = tracks[:, 0].astype(np.int64)
    peds = tracks[:, 1].astype(np.int64)
    by_ped = rows_by_pedestrian(frames, peds)
    wanted: list[np.ndarray] = [np.empty(0, dtype=np.int64)]
    for scene in scenes:
        own = frames[by_ped.get(scene.primary, np.empty(0, dtype=np.int64))]  # sorted: a scene's rows a slice
        lo, hi = np.searchsorted(own, [scene.start_frame, scene.end_frame + 1])
        if lo >= hi:  # lo > hi: a scene that starts after its end
            raise ValueError(
                f"scene {scene.id}: primary {scene.primary} has no row in frames "
                f"{scene.start_frame}-{scene.end_frame}"
            )
        wanted.append(own[lo:hi].copy())  # a view would keep each scene's whole pedestrian alive
    rows = np.flatnonzero(np.isin(frames, np.unique(np.concatenate(wanted))))
    return rows[np.argsort(frames[rows], kind="stable")]


def write_ndjson(
    path: str | Path, scenes: Sequence[SceneSpec], tracks: np.ndarray, fps: float = RECORDED_FPS
) -> np.ndarray:
    """Write a TrajNet++ ndjson file: the scene records, then the track rows they need (see module doc).
    Returns the indices into ``tracks`` of the rows written (a row no scene needs is not)."""
    path = Path(path)
    tracks = _check_tracks(tracks)
    for scene in scenes:
        if scene.fps != fps:
            raise ValueError(f"scene {scene.id} was built at {scene.fps} fps but is written as {fps} fps")
    rows = scene_track_rows(scenes, tracks)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with tmp.open(
            "w", encoding="utf-8"
        ) as out:  # a line at a time: a synthetic set of 10^7 rows is GBs as one string
            for s in scenes:
                scene = SceneRow(s.id, s.primary, s.start_frame, s.end_frame, fps, s.json_tag())
                out.write(trajnet(scene) + "\n")
            for r in rows:
                row = TrackRow(int(tracks[r, 0]), int(tracks[r, 1]), float(tracks[r, 2]), float(tracks[r, 3]))
                out.write(trajnet(row) + "\n")
        replace_durably(tmp, path)  # readers never see a half-written file, nor a power loss an empty one
    finally:
        tmp.unlink(missing_ok=True)  # a write that failed (or was interrupted) half-way leaves nothing
    return rows
