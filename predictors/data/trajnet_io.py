"""Reading TrajNet++ ndjson files: parse and check every line once (``predictors.data.validate``), then build
the scenes through ``trajnetplusplustools.Reader``.

``trajnetplusplustools.Reader`` trusts its input (a blank line or a bad one ends in an exception with no file
name, a track outside every scene is silently ignored), so it never reads a file itself here: it is given the
rows ``validate.parse_ndjson`` checked, which raises ``DatasetFormatError(path, line, reason)`` for the first
problem. Missing steps and NaN coordinates of other agents stay NaN, exactly as ``Reader.paths_to_xy``
defines them; duplicate rows resolve as the Reader resolves them (the later row wins).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from trajnetplusplustools import Reader

from predictors.data.validate import (
    SCENE_KEYS,
    TRACK_KEYS,
    NdjsonContent,
    NdjsonSummary,
    parse_ndjson,
    validate_ndjson,
)
from predictors.errors import DatasetFormatError
from predictors.progress import progress_bar

__all__ = [
    "SCENE_KEYS",
    "TRACK_KEYS",
    "NdjsonSummary",
    "Scene",
    "last_steps",
    "read_scenes",
    "scenes_of",
    "shown_scenes",
    "validate_ndjson",
]


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


class _CheckedReader(Reader):
    """A ``Reader`` over rows already parsed and checked, instead of a file it would parse itself."""

    def read_file(self, input_file: NdjsonContent) -> None:
        # what Reader.read_file does with each line's row, without the parsing
        self.tracks_by_frame = defaultdict(list)
        self.scenes_by_id = {}
        for row in input_file.tracks:
            self.tracks_by_frame[row.frame].append(row)
        for scene in input_file.scenes:
            self.scenes_by_id[scene.scene] = scene
        self._frames = sorted(self.tracks_by_frame)

    def scene(self, scene_id):
        """``Reader.scene`` for ``scene_type="paths"``: the same rows in the same order (by frame, then file
        order), found by bisection over the frames that have rows instead of a lookup of every frame number
        in [s, e] -- a scene spanning 10^9 frames would otherwise take minutes."""
        scene = self.scenes_by_id[scene_id]
        lo = bisect.bisect_left(self._frames, scene.start)
        hi = bisect.bisect_right(self._frames, scene.end)
        track_rows = [r for frame in self._frames[lo:hi] for r in self.tracks_by_frame[frame]]
        return scene_id, self.track_rows_to_paths(scene.pedestrian, track_rows)


def read_scenes(
    path: str | Path, *, require_length: int | None = None, require_fps: float | None = None
) -> list[Scene]:
    """``iter_scenes`` as a list."""
    return list(iter_scenes(path, require_length=require_length, require_fps=require_fps))


def iter_scenes(
    path: str | Path, *, require_length: int | None = None, require_fps: float | None = None
) -> Iterator[Scene]:
    """All scenes of a validated file, in file order, read through ``trajnetplusplustools.Reader``.

    With ``require_length``, every primary must have exactly that many evenly spaced frames (the 21 steps
    of a TrajNet++ training or ground-truth scene); a shorter or gapped scene raises ``DatasetFormatError``.
    With ``require_fps``, so does a scene whose row gives another frame rate (one without "fps" passes, as
    the format allows): the predictors learn and score displacements per step of 1 / fps seconds.
    """
    yield from scenes_of(parse_ndjson(path), require_length=require_length, require_fps=require_fps)


def shown_scenes(content: NdjsonContent, progress: bool | None, **requirements: Any) -> Iterator[Scene]:
    """``scenes_of`` (with its ``requirements``) behind a bar over the file's scenes; ``progress`` None: on a
    terminal only. Building a scene costs time in its rows: a file of dense crowds takes a minute or more."""
    return progress_bar(
        scenes_of(content, **requirements),
        total=len(content.summary.scene_lines),
        desc=f"reading {content.summary.path.name}",
        unit="scene",
        leave=False,
        show=progress,
    )


def scenes_of(
    content: NdjsonContent, *, require_length: int | None = None, require_fps: float | None = None
) -> Iterator[Scene]:
    """``iter_scenes`` of a file ``parse_ndjson`` has already read: a caller that needs its summary too
    (``data stats``) parses it once, not twice."""
    summary = content.summary
    reader = _CheckedReader(content, scene_type="paths")
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
        # close, not equal: a writer's 2.5000001 is 2.5 fps; a 10 % faster file is not
        if (
            require_fps is not None
            and row.fps is not None
            and not math.isclose(row.fps, require_fps, rel_tol=1e-6)
        ):
            raise DatasetFormatError(
                summary.path,
                line,
                f"scene {scene_id} is sampled at {row.fps!r} fps, but the predictors step "
                f"{1 / require_fps:g} s ({require_fps:g} fps); resample the file to {require_fps:g} fps",
            )
        yield (
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


def last_steps(scene: Scene, length: int, path: Path, needs: str) -> Scene:
    """``scene`` cut to its last ``length`` primary frames, what the evaluation scores (a prediction is a
    scene's end; earlier frames may be any); DatasetFormatError when it has fewer (``needs``: what for, after
    "scene S has N steps, ") or they are unevenly spaced."""
    if len(scene.frames) < length:
        raise DatasetFormatError(path, scene.line, f"scene {scene.id} has {len(scene.frames)} steps, {needs}")
    frames = scene.frames[len(scene.frames) - length :]
    if np.unique(np.diff(frames)).size > 1:
        raise DatasetFormatError(
            path, scene.line, f"scene {scene.id} has unevenly spaced frames {frames.tolist()}"
        )
    return dataclasses.replace(scene, frames=frames, xy=scene.xy[len(scene.frames) - length :])


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
