"""Raw BIWI EWAP annotations (``obsmat.txt``) read as TrajNet++'s converter reads them
(``vita-epfl/trajnetplusplusdataset``, ``readers.biwi``), and the converter's temporal split.

Reading: obsmat columns 0, 1, 2 and 4 are frame, pedestrian, x and y (metres, world frame); the frame is
shifted by -1 (the converter's "1-index to 0-index"). Frame ids are otherwise kept (hotel steps by 10, ETH
by 6), both at 2.5 Hz.

The split (``split_frames``) is the converter's too: distinct frames are sorted and cut by fractions, and
scenes are built within each part, so no scene crosses a boundary. TrajNet++ uses 60/20/20; this project
uses train 70 %, val 10 %, test 20 % (for BIWI ETH the test part is the same last 20 % either way).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Final

import numpy as np

from predictors.data.validate import (
    MAX_COORDINATE,
    MAX_FRAME,
    MAX_ID,
    bounded_lines,
    require_file,
)
from predictors.errors import DatasetFormatError, PredictorError

SPLIT_FRACTIONS: Final[tuple[float, float]] = (0.7, 0.1)  # train, val; test is the rest
SPLITS: Final[tuple[str, ...]] = ("train", "val", "test")
EWAP_SEQUENCES: Final[dict[str, str]] = {"biwi_eth": "seq_eth", "biwi_hotel": "seq_hotel"}


# A decimal number as EWAP writes it ("7.8000000e+02"), or nan/inf (refused as not finite). Python's float()
# also takes "1_0" (= 10.0), which is no number in a data file.
_NUMBER: Final = re.compile(
    rb"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[+-]?(?:nan|inf|infinity)", re.IGNORECASE
)
_COLUMNS: Final[tuple[str, ...]] = ("frame", "id", "pos_x", "pos_z", "pos_y", "v_x", "v_z", "v_y")


def read_obsmat(path: str | Path, *, velocities: bool = False) -> np.ndarray:
    """BIWI EWAP ``obsmat.txt`` as ``(R, 4)`` rows ``frame - 1, pedestrian, x, y`` (metres), in file order;
    with ``velocities``, ``(R, 6)`` rows with the file's ``v_x, v_y`` (m/s) after them.

    Each line holds 8 numbers ``frame id pos_x pos_z pos_y v_x v_z v_y`` (z unused), all finite, with an
    integer frame in 1..``MAX_FRAME``, an integer id in 0..``MAX_ID`` and ``|x|, |y| < MAX_COORDINATE``
    (the bounds, and why, are in ``predictors.data.validate``); a sequence needs annotations at two frames
    at least. Anything else raises ``DatasetFormatError`` naming the file and the line.
    """
    path = require_file(path, " (expected a BIWI EWAP obsmat.txt)")
    rows: list[tuple[float, ...]] = []
    seen: dict[tuple[int, int], int] = {}
    for lineno, raw in bounded_lines(path):
        row = _obsmat_row(path, lineno, raw)
        if row is None:
            continue
        key = (int(row[0]), int(row[1]))
        if key in seen:
            raise DatasetFormatError(
                path, lineno, f"pedestrian {key[1]} at frame {key[0]} repeats line {seen[key]}"
            )
        seen[key] = lineno
        rows.append((row[0] - 1.0, *row[1:]))  # the converter's 1- to 0-based frames
    if not rows:
        raise DatasetFormatError(path, None, "no annotation rows")
    if len({frame for frame, _ in seen}) < 2:
        raise DatasetFormatError(
            path, None, "annotations at a single frame; a sequence needs at least two distinct frames"
        )
    table = np.asarray(rows, dtype=np.float64)
    return table if velocities else table[:, :4]


def _obsmat_row(path: Path, lineno: int, raw: bytes) -> tuple[float, ...] | None:
    """``(frame, id, x, y, v_x, v_y)`` of one obsmat line as read (1-based frame), or None for a blank
    line."""
    fields = raw.split()
    if not fields:
        return None
    if len(fields) != len(_COLUMNS):
        raise DatasetFormatError(
            path, lineno, f"expected {len(_COLUMNS)} numeric columns, found {len(fields)}"
        )
    for column, field in zip(_COLUMNS, fields, strict=True):
        if not _NUMBER.fullmatch(field):
            text = field.decode(errors="replace")
            shown = text if len(text) <= 30 else f"{text[:27]}..."
            raise DatasetFormatError(path, lineno, f"non-numeric value {shown!r} in column {column}")
    values = [float(v) for v in fields]
    bad = [column for column, v in zip(_COLUMNS, values, strict=True) if not math.isfinite(v)]
    if bad:
        raise DatasetFormatError(path, lineno, f"{', '.join(bad)} not finite; every column must be a number")
    frame, ped, x, y = values[0], values[1], values[2], values[4]
    if frame != int(frame) or ped != int(ped):
        raise DatasetFormatError(path, lineno, f"frame {frame:g} and id {ped:g} must be integers")
    if not 1 <= frame <= MAX_FRAME:
        raise DatasetFormatError(
            path, lineno, f"frame {frame:g} outside the supported range 1..{MAX_FRAME:.0e}"
        )
    if not 0 <= ped <= MAX_ID:
        raise DatasetFormatError(path, lineno, f"id {ped:g} outside the supported range 0..{MAX_ID:.0e}")
    for name, value in (("pos_x", x), ("pos_y", y)):
        if not abs(value) < MAX_COORDINATE:
            raise DatasetFormatError(
                path,
                lineno,
                f"{name} {value:g} m outside the supported range |{name}| < {MAX_COORDINATE:.0e} m",
            )
    return frame, ped, x, y, values[5], values[7]


def infer_frame_step(frames: np.ndarray) -> int:
    """The sequence's frame increment between consecutive annotated steps (its most common one)."""
    unique = np.unique(np.asarray(frames, dtype=np.int64))
    if unique.size < 2:
        raise PredictorError("cannot infer a frame step from fewer than two distinct frames")
    steps, counts = np.unique(np.diff(unique), return_counts=True)
    return int(steps[np.argmax(counts)])


def split_frames(
    frames: np.ndarray, fractions: tuple[float, float] = SPLIT_FRACTIONS
) -> dict[str, np.ndarray]:
    """Temporal split of the distinct frames: the first ``fractions[0]`` train, the next ``fractions[1]`` val,
    the rest test (index arithmetic as in TrajNet++'s ``convert.write``)."""
    train, val = fractions
    if not (0 <= train and 0 <= val and train + val <= 1):
        raise PredictorError(f"split fractions must be >= 0 and sum to <= 1, got train={train}, val={val}")
    unique = np.unique(np.asarray(frames, dtype=np.int64))
    i_train = int(len(unique) * train)
    i_val = i_train + int(len(unique) * val)
    return {"train": unique[:i_train], "val": unique[i_train:i_val], "test": unique[i_val:]}
