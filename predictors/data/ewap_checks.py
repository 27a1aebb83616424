"""Plausibility checks of raw BIWI EWAP tracks before ``data prepare`` converts them: the converter labels
every scene 2.5 fps (0.4 s per annotated step) whatever the file's rate, so a file annotated at another rate
would be prepared without a word and scored wrongly; and a step no walker makes (a reused id, a tracker jump)
ends up inside a primary's 21 steps.

Both read the file's own evidence: obsmat rows carry positions and velocities, so the time between two
annotated steps of a pedestrian is ``|dp| / |v|``. BIWI's real files give 0.400 s (seq_eth and seq_hotel,
median over tracks), and their fastest step is under 4.6 m/s.
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

import numpy as np

from crowdsim.world import RECORDED_DT, RECORDED_FPS
from predictors.errors import DatasetFormatError
from predictors.text_table import counted

# The estimate of a 0.4 s file lands within 1 % of it; a 10 Hz file gives 0.1 s, a 1 Hz one 1 s.
STEP_RANGE: Final[tuple[float, float]] = (0.3, 0.5)
# Below this speed |dp| / |v| is mostly rounding and annotation noise (standing people), not time.
MIN_SPEED: Final[float] = 0.2  # m/s
# A running pace: 2 m in one 0.4 s step. BIWI's fastest step is 4.6 m/s (seq_eth), so real data is not noted.
MAX_SPEED: Final[float] = 5.0  # m/s


def _consecutive(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(a, b)`` into ``rows`` of each pair of a pedestrian's consecutive rows (by frame)."""
    order = np.lexsort((rows[:, 0], rows[:, 1]))
    same = rows[order[1:], 1] == rows[order[:-1], 1]
    return order[:-1][same], order[1:][same]


def step_seconds(rows: np.ndarray, frame_step: int) -> tuple[float, int] | None:
    """The time per annotated step the velocity columns imply (``rows``: ``read_obsmat(velocities=True)``):
    over each track's steps of one ``frame_step`` where the pedestrian moves, the median of ``|dp| / |v|``
    (``|v|`` the mean of the two rows' speeds), then the median over tracks, so that a few bad tracks (a
    reused id) do not move it. With the number of tracks used; None when no track moves (zero velocity
    columns say nothing about time)."""
    a, b = _consecutive(rows)
    speed = (np.hypot(rows[a, 4], rows[a, 5]) + np.hypot(rows[b, 4], rows[b, 5])) / 2
    keep = (rows[b, 0] - rows[a, 0] == frame_step) & (speed > MIN_SPEED)
    a, b, speed = a[keep], b[keep], speed[keep]
    if not a.size:
        return None
    ratio = np.hypot(rows[b, 2] - rows[a, 2], rows[b, 3] - rows[a, 3]) / speed
    peds = rows[a, 1]
    medians = [float(np.median(ratio[peds == p])) for p in np.unique(peds)]
    return float(np.median(medians)), len(medians)


def check_step_seconds(path: Path, rows: np.ndarray, frame_step: int) -> None:
    """``DatasetFormatError`` naming ``path`` when its velocity columns imply a time per annotated step far
    from 0.4 s: the scenes would be labelled 2.5 fps and every displacement read at the wrong rate."""
    found = step_seconds(rows, frame_step)
    if found is None:
        return
    seconds, tracks = found
    low, high = STEP_RANGE
    if not low <= seconds <= high:
        raise DatasetFormatError(
            path,
            None,
            f"its velocity columns imply {seconds:.3f} s per annotated step ({1 / seconds:.3g} fps, "
            f"median over {tracks} tracks), but `data prepare` converts BIWI's {RECORDED_FPS:g} fps "
            f"annotations ({RECORDED_DT} s a step); resample the file to {RECORDED_FPS:g} fps first",
        )


def fast_steps_note(path: Path, rows: np.ndarray, frame_step: int) -> str | None:
    """A note naming ``path`` when a pedestrian's consecutive rows are further apart than ``MAX_SPEED``
    allows in the time between them (``frame_step`` frames a 0.4 s step): a reused id or a tracker jump,
    which a scene keeps as a leap of its primary. None when there is none. Frames as the file numbers them."""
    a, b = _consecutive(rows)
    seconds = (rows[b, 0] - rows[a, 0]) / frame_step * RECORDED_DT
    metres = np.hypot(rows[b, 2] - rows[a, 2], rows[b, 3] - rows[a, 3])
    fast = np.flatnonzero(metres > MAX_SPEED * seconds)
    if not fast.size:
        return None
    first = fast[np.argmin(rows[a[fast], 0])]
    i, j = a[first], b[first]
    return (
        f"note: {path}: {counted(int(fast.size), 'step')} of a pedestrian faster than "
        f"{MAX_SPEED:g} m/s (e.g. pedestrian {rows[i, 1]:.0f}, frames {rows[i, 0] + 1:.0f} to "
        f"{rows[j, 0] + 1:.0f}: {metres[first]:.1f} m in {seconds[first]:.1f} s); an id reused by another "
        "person, or a tracker jump? The scenes keep them as they are"
    )
