"""The one validation layer of the data formats: every TrajNet++ ndjson file is read through ``parse_ndjson``
here (raw obsmat files through ``ewap.read_obsmat``, with the bounds below), and every problem becomes
``DatasetFormatError(path, line, reason)``, printed by the CLI as ``<file>:<line>: <reason>``.

``trajnetplusplustools.Reader`` trusts its input: a blank line, a bad line or a huge integer ends in a
``JSONDecodeError``, ``KeyError`` or ``OverflowError`` with no file name, and a track outside every scene is
silently ignored. So the file is parsed and checked here, line by line, exactly once, and ``trajnet_io`` hands
the checked records to the Reader instead of letting it re-read the file. What a valid TrajNet++ file means
to the Reader does not change: the same rows, in the same order, with the same fields.

Checked: each non-blank line is a JSON object holding exactly one ``scene`` or ``track`` object (blank lines
are skipped); the keys each needs are present with integer ids/frames and numeric coordinates, all within
the bounds below, and a track's optional ``prediction_number`` and ``scene_id`` are null or such integers
too; scene ids are unique; a pedestrian has one position per frame (the Reader keeps one row per pedestrian
and frame whatever those two fields say; an identical repeated row passes); every track frame lies within
some scene's [s, e]; every scene's primary has a track row in its frame range, and a position (not NaN) at
each of those rows. NaN is TrajNet++'s own "not observed" for other agents (Python's json and the Reader
accept it); an infinity is never a position. A file with no records at all is a valid, empty dataset (a split
can be empty).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
from trajnetplusplustools import SceneRow, TrackRow

from predictors.errors import DatasetFormatError

# Sane bounds, far beyond any real dataset, that keep every later computation exact:
# * frames: TrajNet++ and EWAP frames are video frame numbers (BIWI stops near 18 000). 10^9 frames is over a
#   year of 25 fps video, fits int32, is exact in float64 (obsmat values are read as floats) and leaves int64
#   arithmetic on frame ranges (differences, strides, sums) far from overflow -- a frame of 1e30 used to
#   wrap into negative frame ranges.
# * ids: pedestrian and scene ids are counters (a few thousand in TrajNet++); the same bound keeps them in
#   int32/int64 arrays without wrapping.
# * coordinates: metres in a world frame around one scene (TrajNet++ stays within +-30 m). Below 10^5 m the
#   float32 arrays of training keep better than 1 cm of resolution and squared distances cannot overflow.
MAX_FRAME: Final[int] = 10**9
MAX_ID: Final[int] = 10**9
MAX_COORDINATE: Final[float] = 1e5  # metres, exclusive
MAX_FPS: Final[float] = 1e4  # no annotation runs at more than 10 kHz
# A TrajNet++ record is under 200 bytes; the cap bounds memory and parse time for a hostile line.
MAX_LINE_BYTES: Final[int] = 1 << 20
UTF8_BOM: Final[bytes] = b"\xef\xbb\xbf"

TRACK_KEYS: Final[tuple[str, ...]] = ("f", "p", "x", "y")
# fields of a TrajNet++ prediction file's tracks, optional: the Reader keeps them on its rows, nothing more
OPTIONAL_TRACK_KEYS: Final[tuple[str, ...]] = ("prediction_number", "scene_id")
SCENE_KEYS: Final[tuple[str, ...]] = ("id", "p", "s", "e")


@dataclass(frozen=True)
class NdjsonSummary:
    """What validation learned about a file, without building scenes."""

    path: Path
    scene_lines: dict[int, int]  # scene id -> 1-based line number of its scene record
    n_tracks: int  # track records
    pedestrians: frozenset[int]  # distinct pedestrian ids among the tracks
    frames: frozenset[int]  # distinct frame ids among the tracks


@dataclass(frozen=True)
class NdjsonContent:
    """A validated file: its records as the Reader's rows, in file order, and the summary."""

    summary: NdjsonSummary
    tracks: list[TrackRow]
    scenes: list[SceneRow]


def require_file(path: str | Path, what: str = "") -> Path:
    """``path`` as a ``Path`` if it names a regular file, else ``DatasetFormatError`` saying what it is.

    ``what`` completes "no such file" (e.g. " (expected a BIWI EWAP obsmat.txt)"). A FIFO or device is
    refused too: reading one can block forever.
    """
    path = Path(path)
    try:
        if path.is_file():
            return path
        exists, is_dir = path.exists(), path.is_dir()
    except OSError as exc:  # e.g. a path component without search permission, a name too long
        raise DatasetFormatError(path, None, f"cannot access ({exc.strerror or exc})") from None
    if is_dir:
        raise DatasetFormatError(path, None, f"is a directory, not a data file{what}")
    if exists:
        raise DatasetFormatError(path, None, f"not a regular file{what}")
    raise DatasetFormatError(path, None, f"no such file{what}")


def read_error(path: Path, line: int | None, exc: OSError) -> DatasetFormatError:
    """The error for an ``OSError`` while opening or reading ``path`` (``line``: where reading stopped)."""
    return DatasetFormatError(path, line, f"cannot read ({exc.strerror or exc})")


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


def _check_int(path: Path, lineno: int, kind: str, key: str, value: object, high: int) -> None:
    if not isinstance(value, int) or isinstance(value, bool):
        raise DatasetFormatError(path, lineno, f"{kind} {key!r} must be an integer, got {_show(value)}")
    if not 0 <= value <= high:
        raise DatasetFormatError(
            path, lineno, f"{kind} {key!r} is {_show(value)}, outside the supported range 0..{high:.0e}"
        )


def _show(value: object) -> str:
    """``repr`` of a value from the file, cut short (an integer can have thousands of digits)."""
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:37]}..."


def _check_track(path: Path, lineno: int, track: dict) -> None:
    _check_int(path, lineno, "track", "f", track["f"], MAX_FRAME)
    _check_int(path, lineno, "track", "p", track["p"], MAX_ID)
    for key in OPTIONAL_TRACK_KEYS:
        if track.get(key) is not None:
            _check_int(path, lineno, "track", key, track[key], MAX_ID)
    for key in ("x", "y"):
        value = track[key]
        if not _is_number(value):
            raise DatasetFormatError(path, lineno, f"track {key!r} must be a number, got {_show(value)}")
        if isinstance(value, float) and math.isnan(value):
            continue  # TrajNet++'s "not observed" (refused later for a scene's primary)
        if isinstance(value, float) and math.isinf(value):
            raise DatasetFormatError(path, lineno, f"track {key!r} is infinite")
        if not abs(value) < MAX_COORDINATE:  # an int of any size compares without overflow
            raise DatasetFormatError(
                path,
                lineno,
                f"track {key!r} is {_show(value)} m, outside the supported range "
                f"|{key}| < {MAX_COORDINATE:.0e} m",
            )


def _check_scene(path: Path, lineno: int, scene: dict) -> None:
    _check_int(path, lineno, "scene", "id", scene["id"], MAX_ID)
    _check_int(path, lineno, "scene", "p", scene["p"], MAX_ID)
    _check_int(path, lineno, "scene", "s", scene["s"], MAX_FRAME)
    _check_int(path, lineno, "scene", "e", scene["e"], MAX_FRAME)
    if scene["s"] > scene["e"]:
        raise DatasetFormatError(
            path, lineno, f"scene starts at frame {scene['s']} after its end {scene['e']}"
        )
    fps = scene.get("fps")
    # the comparisons are False for NaN and refuse infinities and huge integers without converting them
    if fps is not None and (not _is_number(fps) or not 0 < fps <= MAX_FPS):
        raise DatasetFormatError(
            path, lineno, f"scene 'fps' must be a number in (0, {MAX_FPS:.0e}], got {_show(fps)}"
        )


_BLANK: Final = object()


def _parse_line(path: Path, lineno: int, raw: bytes) -> Any:
    """The JSON value of one line, or ``_BLANK`` for a blank line."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DatasetFormatError(path, lineno, f"not UTF-8 text ({exc.reason})") from None
    if not text.strip():
        return _BLANK
    try:
        # without its line end: an error at the end of a cut line was placed at column 1 of the next line
        return json.loads(text.rstrip("\r\n"))
    except json.JSONDecodeError as exc:
        # some of json's messages end in " at" ("Unterminated string starting at"), as they name the place
        reason = f"invalid JSON ({exc.msg.removesuffix(' at')} at column {exc.colno})"
        raise DatasetFormatError(path, lineno, reason) from None
    except RecursionError:
        raise DatasetFormatError(path, lineno, "invalid JSON (nested too deeply)") from None
    except ValueError as exc:  # an integer literal beyond Python's digit limit (sys.get_int_max_str_digits)
        raise DatasetFormatError(path, lineno, f"invalid JSON ({str(exc).split(';')[0]})") from None


def bounded_lines(path: Path) -> Iterator[tuple[int, bytes]]:
    """``(line number, bytes)`` of every line, each at most ``MAX_LINE_BYTES`` long; a read error names the
    file and line. Every data reader goes through it (ndjson here, obsmat in ``ewap``)."""
    lineno = 0
    try:
        with path.open("rb") as handle:
            while raw := handle.readline(MAX_LINE_BYTES + 1):
                lineno += 1
                if lineno == 1 and raw.startswith(UTF8_BOM):
                    # TrajNet++'s tools read neither format with one (json.loads and float() refuse it)
                    raise DatasetFormatError(
                        path, 1, "starts with a UTF-8 byte-order mark; save the file without one"
                    )
                if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
                    raise DatasetFormatError(path, lineno, f"line longer than {MAX_LINE_BYTES} bytes")
                yield lineno, raw
    except OSError as exc:
        raise read_error(path, lineno or None, exc) from None


def parse_ndjson(path: str | Path) -> NdjsonContent:
    """Parse and check a TrajNet++ ndjson file (module doc); ``DatasetFormatError`` at the first problem."""
    path = require_file(path)
    scenes: dict[int, tuple[int, int, int, int]] = {}  # id -> (line, primary, s, e)
    track_lines: list[int] = []
    track_rows: list[TrackRow] = []
    scene_rows: list[SceneRow] = []
    nan_rows: list[tuple[int, int, int]] = []  # (frame, pedestrian, line) of tracks with a NaN coordinate
    for lineno, raw in bounded_lines(path):
        record = _parse_line(path, lineno, raw)
        if record is _BLANK:
            continue
        if not isinstance(record, dict) or ("scene" in record) == ("track" in record):
            raise DatasetFormatError(
                path, lineno, 'expected an object with exactly one of "scene" or "track"'
            )
        if "track" in record:
            track = _check_record(path, lineno, "track", record["track"], TRACK_KEYS)
            _check_track(path, lineno, track)
            track_lines.append(lineno)
            # the fields trajnetplusplustools.Reader.read_file takes
            row = TrackRow(
                track["f"],
                track["p"],
                track["x"],
                track["y"],
                track.get("prediction_number"),
                track.get("scene_id"),
            )
            track_rows.append(row)
            if math.isnan(row.x) or math.isnan(row.y):
                nan_rows.append((row.frame, row.pedestrian, lineno))
        else:
            scene = _check_record(path, lineno, "scene", record["scene"], SCENE_KEYS)
            _check_scene(path, lineno, scene)
            if scene["id"] in scenes:
                first = scenes[scene["id"]][0]
                raise DatasetFormatError(
                    path, lineno, f"scene id {scene['id']} repeats the one on line {first}"
                )
            scenes[scene["id"]] = (lineno, scene["p"], scene["s"], scene["e"])
            scene_rows.append(
                SceneRow(scene["id"], scene["p"], scene["s"], scene["e"], scene.get("fps"), scene.get("tag"))
            )
    # every value is bounded above, so these int64 arrays cannot overflow
    rows = np.asarray([(r.frame, r.pedestrian) for r in track_rows], dtype=np.int64).reshape(-1, 2)
    spans = np.asarray([(s, e) for _, _, s, e in scenes.values()], dtype=np.int64).reshape(-1, 2)
    _check_tracks_inside_scenes(path, rows[:, 0], track_lines, spans)
    _check_no_conflicting_rows(path, track_rows, track_lines)
    _check_primaries_present(path, rows, scenes)
    _check_primaries_observed(path, nan_rows, scenes)
    summary = NdjsonSummary(
        path=path,
        scene_lines={sid: v[0] for sid, v in scenes.items()},
        n_tracks=len(track_rows),
        pedestrians=frozenset(rows[:, 1].tolist()),
        frames=frozenset(rows[:, 0].tolist()),
    )
    return NdjsonContent(summary, track_rows, scene_rows)


def validate_ndjson(path: str | Path) -> NdjsonSummary:
    """Check every line of a TrajNet++ ndjson file (module doc); raise ``DatasetFormatError`` at the first
    bad one."""
    return parse_ndjson(path).summary


def _check_no_conflicting_rows(path: Path, rows: list[TrackRow], lines: list[int]) -> None:
    """One position per pedestrian and frame: a second row with another position was silently dropped by
    the reader, so which one a model trained on depended on the order of the lines. The key is the reader's
    own (``Reader.paths_to_xy`` places a row by pedestrian and frame, ignoring ``prediction_number`` and
    ``scene_id``, so rows differing only there overwrote each other too). A repeated identical row is
    harmless and passes."""
    first: dict[tuple[int, int], int] = {}  # (frame, pedestrian) -> index of its first row
    for index, row in enumerate(rows):
        key = (row.frame, row.pedestrian)
        k = first.setdefault(key, index)
        if k != index and not _same_position(rows[k], row):
            raise DatasetFormatError(
                path,
                lines[index],
                f"pedestrian {row.pedestrian} at frame {row.frame} has another position on line {lines[k]} "
                f"({_show(rows[k].x)}, {_show(rows[k].y)} against {_show(row.x)}, {_show(row.y)})",
            )


def _same_position(a: TrackRow, b: TrackRow) -> bool:
    return all(u == v or (math.isnan(u) and math.isnan(v)) for u, v in ((a.x, b.x), (a.y, b.y)))


def _check_tracks_inside_scenes(path: Path, frames: np.ndarray, lines: list[int], spans: np.ndarray) -> None:
    """Every track frame must fall in some scene's [s, e]; such a row could never be read."""
    if frames.size == 0:
        return
    if spans.size == 0:
        raise DatasetFormatError(
            path, lines[0], f"track at frame {int(frames[0])}, but the file has no scene record"
        )
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


def rows_by_pedestrian(frames: np.ndarray, peds: np.ndarray) -> dict[int, np.ndarray]:
    """Each pedestrian's row indices, sorted by frame (stable): one sort for all rows, where a scan of every
    row per pedestrian or per scene is quadratic in a large file (`data synth`'s 1 000 episodes: 48 s)."""
    if not len(peds):
        return {}
    order = np.lexsort((frames, peds))
    ids, first = np.unique(peds[order], return_index=True)
    return {int(ped): rows for ped, rows in zip(ids, np.split(order, first[1:]), strict=True)}


def _check_primaries_present(
    path: Path, rows: np.ndarray, scenes: dict[int, tuple[int, int, int, int]]
) -> None:
    by_ped = {ped: rows[own, 0] for ped, own in rows_by_pedestrian(rows[:, 0], rows[:, 1]).items()}
    for sid, (lineno, primary, s, e) in scenes.items():
        frames = by_ped.get(primary)
        if frames is None or not np.any((frames >= s) & (frames <= e)):
            raise DatasetFormatError(
                path, lineno, f"scene {sid}: primary pedestrian {primary} has no track row in frames {s}-{e}"
            )


def _check_primaries_observed(
    path: Path, nan_rows: list[tuple[int, int, int]], scenes: dict[int, tuple[int, int, int, int]]
) -> None:
    """A scene's time axis is its primary's frames, so the primary needs a position at each of them: a NaN
    there would leave the primary unobserved (no origin to centre on, no ground truth to score)."""
    if not nan_rows:
        return
    by_primary: dict[int, list[tuple[int, int, int]]] = {}
    for sid, (_, primary, s, e) in scenes.items():
        by_primary.setdefault(primary, []).append((sid, s, e))
    for frame, ped, lineno in nan_rows:
        for sid, s, e in by_primary.get(ped, ()):
            if s <= frame <= e:
                raise DatasetFormatError(
                    path,
                    lineno,
                    f"scene {sid}: primary pedestrian {ped} has no position (NaN) at frame {frame}; "
                    "a scene's primary must be observed at each of its rows",
                )
