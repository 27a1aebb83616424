"""Reading TrajNet++ ndjson files: validate every line, then read through ``trajnetplusplustools.Reader``.

``trajnetplusplustools.Reader`` trusts its input: a bad line ends in a ``KeyError`` or ``JSONDecodeError``
with no file name, and a track outside every scene is silently ignored. So each file is first validated
line by line (``validate_ndjson``), which raises ``DatasetFormatError(path, line, reason)`` for the first
problem, and only then handed to ``Reader``. Missing steps and NaN coordinates stay NaN, exactly as
``Reader.paths_to_xy`` defines them; duplicate rows resolve as the Reader resolves them (the later row wins).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from trajnetplusplustools import Reader

from predictors.errors import DatasetFormatError

TRACK_KEYS = ("f", "p", "x", "y")
SCENE_KEYS = ("id", "p", "s", "e")


@dataclass(frozen=True)
class NdjsonSummary:
    """What validation learned about a file, without building scenes."""

    path: Path
    scene_lines: dict[int, int]  # scene id -> 1-based line number of its scene record
    n_tracks: int  # track records
    pedestrians: frozenset[int]  # distinct pedestrian ids among the tracks
    frames: frozenset[int]  # distinct frame ids among the tracks


@dataclass(frozen=True)
class Scene:
    """One TrajNet++ scene as arrays; agent 0 is the primary pedestrian."""

    id: int
    primary: int
    start: int  # first frame id
    end: int  # last frame id
    fps: float | None
    tag: object  # [type, [sub-types]] as in the file, or 0 where uncategorised
    frames: np.ndarray  # (T,) int64, the primary's frame ids in increasing order
    agents: np.ndarray  # (N,) int64 pedestrian ids, primary first, then in order of appearance
    xy: np.ndarray  # (T, N, 2) float64 metres, NaN where an agent has no row at that frame
    line: int  # line of the scene record in its file


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _check_record(path: Path, lineno: int, kind: str, record: object, keys: tuple[str, ...]) -> dict:
    if not isinstance(record, dict):
        raise DatasetFormatError(path, lineno, f'"{kind}" must be a JSON object, got {type(record).__name__}')
    missing = [k for k in keys if k not in record]
    if missing:
        raise DatasetFormatError(
            path, lineno, f"{kind} record lacks key(s) {missing}; a {kind} needs {list(keys)}"
        )
    return record


def _check_track(path: Path, lineno: int, track: dict) -> None:
    for key in ("f", "p"):
        if not _is_int(track[key]):
            raise DatasetFormatError(path, lineno, f"track {key!r} must be an integer, got {track[key]!r}")
    for key in ("x", "y"):
        value = track[key]
        if not _is_number(value):
            raise DatasetFormatError(path, lineno, f"track {key!r} must be a number, got {value!r}")
        # NaN is TrajNet++'s own "not observed"; an infinity is never a position.
        if math.isinf(value):
            raise DatasetFormatError(path, lineno, f"track {key!r} is infinite")


def _check_scene(path: Path, lineno: int, scene: dict) -> None:
    for key in SCENE_KEYS:
        if not _is_int(scene[key]):
            raise DatasetFormatError(path, lineno, f"scene {key!r} must be an integer, got {scene[key]!r}")
    if scene["s"] > scene["e"]:
        raise DatasetFormatError(
            path, lineno, f"scene starts at frame {scene['s']} after its end {scene['e']}"
        )
    fps = scene.get("fps")
    if fps is not None and (not _is_number(fps) or not fps > 0):
        raise DatasetFormatError(path, lineno, f"scene 'fps' must be a positive number, got {fps!r}")


def validate_ndjson(path: str | Path) -> NdjsonSummary:
    """Check every line of a TrajNet++ ndjson file; raise ``DatasetFormatError`` at the first bad one.

    Checked: each non-blank line is a JSON object holding a ``scene`` or a ``track``; the keys each needs
    are present with integer ids/frames and numeric coordinates; scene ids are unique; every track frame lies
    within some scene's [s, e]; every scene's primary has a track row in its frame range. A file with no
    records at all is a valid, empty dataset (a split can be empty).
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetFormatError(path, None, "no such file")
    scenes: dict[int, tuple[int, int, int, int]] = {}  # id -> (line, primary, s, e)
    track_lines: list[int] = []
    track_rows: list[tuple[int, int]] = []  # (frame, pedestrian)
    with path.open("rb") as handle:
        for lineno, raw in enumerate(handle, start=1):
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise DatasetFormatError(path, lineno, f"not UTF-8 text ({exc.reason})") from None
            if not text.strip():
                continue
            try:
                record = json.loads(text)
            except json.JSONDecodeError as exc:
                raise DatasetFormatError(
                    path, lineno, f"invalid JSON ({exc.msg} at column {exc.colno})"
                ) from None
            if not isinstance(record, dict) or ("scene" in record) == ("track" in record):
                raise DatasetFormatError(
                    path, lineno, 'expected an object with exactly one of "scene" or "track"'
                )
            if "track" in record:
                track = _check_record(path, lineno, "track", record["track"], TRACK_KEYS)
                _check_track(path, lineno, track)
                track_lines.append(lineno)
                track_rows.append((track["f"], track["p"]))
            else:
                scene = _check_record(path, lineno, "scene", record["scene"], SCENE_KEYS)
                _check_scene(path, lineno, scene)
                if scene["id"] in scenes:
                    first = scenes[scene["id"]][0]
                    raise DatasetFormatError(
                        path, lineno, f"scene id {scene['id']} repeats the one on line {first}"
                    )
                scenes[scene["id"]] = (lineno, scene["p"], scene["s"], scene["e"])
    rows = np.asarray(track_rows, dtype=np.int64).reshape(-1, 2)
    spans = np.asarray([(s, e) for _, _, s, e in scenes.values()], dtype=np.int64)
    _check_tracks_inside_scenes(path, rows[:, 0], track_lines, spans)
    _check_primaries_present(path, rows, scenes)
    return NdjsonSummary(
        path=path,
        scene_lines={sid: v[0] for sid, v in scenes.items()},
        n_tracks=len(track_rows),
        pedestrians=frozenset(rows[:, 1].tolist()),
        frames=frozenset(rows[:, 0].tolist()),
    )


def _check_tracks_inside_scenes(path: Path, frames: np.ndarray, lines: list[int], spans: np.ndarray) -> None:
    """Every track frame must fall in some scene's [s, e]; such a row could never be read."""
    if frames.size == 0:
        return
    order = np.argsort(spans[:, 0], kind="stable")
    starts = spans[order, 0]
    # running maximum of the ends: a frame is covered iff, among scenes starting at or before it,
    # the furthest end reaches it
    reach = np.maximum.accumulate(spans[order, 1])
    idx = np.searchsorted(starts, frames, side="right") - 1
    covered = (idx >= 0) & (reach[np.maximum(idx, 0)] >= frames)
    if not covered.all():
        bad = int(np.flatnonzero(~covered)[0])
        raise DatasetFormatError(
            path, lines[bad], f"track frame {int(frames[bad])} lies outside every scene's [s, e] frame range"
        )


def _check_primaries_present(
    path: Path, rows: np.ndarray, scenes: dict[int, tuple[int, int, int, int]]
) -> None:
    by_ped: dict[int, np.ndarray] = {}
    if rows.size:
        order = np.lexsort((rows[:, 0], rows[:, 1]))
        peds, first = np.unique(rows[order, 1], return_index=True)
        for k, ped in enumerate(peds):
            stop = first[k + 1] if k + 1 < len(first) else len(order)
            by_ped[int(ped)] = rows[order[first[k] : stop], 0]
    for sid, (lineno, primary, s, e) in scenes.items():
        frames = by_ped.get(primary)
        if frames is None or not np.any((frames >= s) & (frames <= e)):
            raise DatasetFormatError(
                path, lineno, f"scene {sid}: primary pedestrian {primary} has no track row in frames {s}-{e}"
            )


def read_scenes(path: str | Path, *, require_length: int | None = None) -> list[Scene]:
    """All scenes of a validated file, in file order, read through ``trajnetplusplustools.Reader``.

    With ``require_length``, every primary must have exactly that many evenly spaced frames (the 21 steps
    of a TrajNet++ training or ground-truth scene); a shorter or gapped scene raises ``DatasetFormatError``.
    """
    summary = validate_ndjson(path)
    reader = Reader(str(summary.path), scene_type="paths")
    scenes = []
    for scene_id, paths in reader.scenes():
        row = reader.scenes_by_id[scene_id]
        line = summary.scene_lines[scene_id]
        xy = Reader.paths_to_xy(paths)
        primary_frames = {r.frame for r in paths[0]}
        frames = np.asarray(sorted(primary_frames), dtype=np.int64)
        # the agents (and their order) that Reader.paths_to_xy keeps: those with a row at a primary frame
        present = {r.pedestrian for path in paths for r in path if r.frame in primary_frames}
        agents = np.asarray([p[0].pedestrian for p in paths if p[0].pedestrian in present], dtype=np.int64)
        if require_length is not None:
            _check_length(summary.path, line, scene_id, row.pedestrian, frames, require_length)
        scenes.append(
            Scene(
                id=scene_id,
                primary=row.pedestrian,
                start=row.start,
                end=row.end,
                fps=row.fps,
                tag=row.tag if row.tag is not None else 0,
                frames=frames,
                agents=agents,
                xy=xy,
                line=line,
            )
        )
    return scenes


def _check_length(
    path: Path, line: int, scene_id: int, primary: int, frames: np.ndarray, length: int
) -> None:
    if len(frames) != length:
        raise DatasetFormatError(
            path,
            line,
            f"scene {scene_id}: primary pedestrian {primary} has {len(frames)} frames, need {length} "
            "(observed + predicted steps)",
        )
    steps = np.diff(frames)
    if steps.size and not np.all(steps == steps[0]):
        raise DatasetFormatError(
            path,
            line,
            f"scene {scene_id}: primary pedestrian {primary} has unevenly spaced frames {frames.tolist()}",
        )
