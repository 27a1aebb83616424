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

from pathlib import Path
from typing import Final

import numpy as np

from predictors.errors import DatasetFormatError, PredictorError

SPLIT_FRACTIONS: Final[tuple[float, float]] = (0.7, 0.1)  # train, val; test is the rest
SPLITS: Final[tuple[str, ...]] = ("train", "val", "test")
EWAP_SEQUENCES: Final[dict[str, str]] = {"biwi_eth": "seq_eth", "biwi_hotel": "seq_hotel"}


def read_obsmat(path: str | Path) -> np.ndarray:
    """BIWI EWAP ``obsmat.txt`` as ``(R, 4)`` rows ``frame - 1, pedestrian, x, y`` (metres), in file order.

    Each line holds 8 numbers ``frame id pos_x pos_z pos_y v_x v_z v_y`` (z unused); anything else raises
    ``DatasetFormatError`` naming the line.
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetFormatError(path, None, "no such file (expected a BIWI EWAP obsmat.txt)")
    rows: list[tuple[float, float, float, float]] = []
    seen: dict[tuple[int, int], int] = {}
    with path.open("rb") as handle:
        for lineno, raw in enumerate(handle, start=1):
            fields = raw.split()
            if not fields:
                continue
            if len(fields) != 8:
                raise DatasetFormatError(path, lineno, f"expected 8 numeric columns, found {len(fields)}")
            try:
                values = [float(v) for v in fields]
            except ValueError:
                raise DatasetFormatError(
                    path, lineno, f"non-numeric value in {raw.decode(errors='replace')!r}"
                ) from None
            frame, ped, x, y = values[0], values[1], values[2], values[4]
            if not all(np.isfinite((frame, ped, x, y))):
                raise DatasetFormatError(path, lineno, "frame, id and coordinates must be finite")
            if frame != int(frame) or ped != int(ped) or frame < 1:
                raise DatasetFormatError(
                    path, lineno, f"frame {frame} and id {ped} must be integers, frame >= 1"
                )
            key = (int(frame), int(ped))
            if key in seen:
                raise DatasetFormatError(
                    path, lineno, f"pedestrian {key[1]} at frame {key[0]} repeats line {seen[key]}"
                )
            seen[key] = lineno
            rows.append((frame - 1.0, ped, x, y))  # the converter's shift from 1- to 0-based frames
    if not rows:
        raise DatasetFormatError(path, None, "no annotation rows")
    return np.asarray(rows, dtype=np.float64)


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
