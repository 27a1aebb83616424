"""The recordings a replayed crowd plays back (``[env] crowd = "eth" | "hotel" | "eth_test" | "hotel_test"``,
or their reactive replays "eth_reactive", ..., crowdsim.replay), read from the raw BIWI annotations of the
data directory (``$CROWDMPC_DATA``: ``raw_ewap/seq_eth/obsmat.txt``).

Read as TrajNet++'s converter reads them (predictors.data.ewap), once per process and data directory: a
sweep's worker runs thousands of episodes from one recording. The raw files, not the prepared TrajNet++
scenes: those cut the tracks into 8-second windows, and an episode lasts up to 40 s.

The shipped nets were trained under the ``paper`` protocol on the first 70 % of the frames of both sequences
(and validated on the next 10 %): a whole sequence replays people they have seen. "eth_test" and
"hotel_test" replay the last 20 % alone, the TrajNet++ test split (``predictors.data.ewap.split_frames``),
which none of them saw: ETH's spans 143 s, Hotel's 147 s, so their episodes' windows overlap more.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Final

import numpy as np

from crowdsim.replay import REACTIVE, REACTIVE_SUFFIX, Recording
from pipelines.errors import PipelineError

# --crowd's help, simulate's and sweep's
CROWD_HELP: Final[str] = (
    "orca (default) | BIWI's people replayed: eth, hotel, or their test splits eth_test, hotel_test; each "
    "_reactive: yielding to the robots (docs/replayed_crowds.md)"
)
SEQUENCES: Final[dict[str, str]] = {
    "eth": "seq_eth",
    "hotel": "seq_hotel",
    "eth_test": "seq_eth",
    "hotel_test": "seq_hotel",
}


def recording(crowd: str, data_dir: str | Path | None = None) -> Recording:
    """The ``Recording`` of ``crowd`` (a key of ``SEQUENCES``, or its reactive replay: "eth_test_reactive"
    plays "eth_test") from ``data_dir`` (default: ``$CROWDMPC_DATA``); PipelineError naming what is missing,
    DatasetFormatError for a broken file."""
    path = recording_path(crowd, data_dir)
    return _read(crowd.removesuffix(REACTIVE_SUFFIX), path, os.stat(path).st_mtime_ns)


def recording_sha256(crowd: str, data_dir: str | Path | None = None) -> str:
    """The sha256 of the file ``crowd`` replays, for the records: a sweep resumed with another data
    directory (or an edited file) would have mixed two crowds under one cell key."""
    path = recording_path(crowd, data_dir)
    stat = os.stat(path)
    return _sha256(path, stat.st_mtime_ns, stat.st_size)


def crowd_sha256(crowd: str) -> str | None:
    """``recording_sha256`` of a replayed crowd, None for ORCA's (it replays no file): what a run records
    beside ``crowd``, so that ``crowdmpc compare`` tells two files' crowds apart."""
    return None if crowd == "orca" else recording_sha256(crowd)


@functools.lru_cache(maxsize=4)
def _sha256(path: Path, mtime_ns: int, size: int) -> str:
    import hashlib

    with open(path, "rb") as file:
        return hashlib.file_digest(file, "sha256").hexdigest()


def recording_path(crowd: str, data_dir: str | Path | None = None) -> Path:
    """The raw annotation file ``crowd`` replays (see ``recording``)."""
    from predictors.data.locate import DATA_ENV, raw_ewap_dir, resolve_data_dir

    replayed = [*SEQUENCES, *REACTIVE]
    if crowd not in replayed:
        raise PipelineError(f"crowd {crowd!r} is no recording; choose from {replayed}")
    sequence = SEQUENCES[crowd.removesuffix(REACTIVE_SUFFIX)]
    if data_dir is None and not os.environ.get(DATA_ENV):
        raise PipelineError(
            f"crowd {crowd!r} replays the raw BIWI tracks: set {DATA_ENV} to the folder holding raw_ewap/ "
            "(data/README.md)"
        )
    directory = resolve_data_dir(data_dir).resolve()
    raw = raw_ewap_dir(directory)
    if raw is None:
        raise PipelineError(
            f"crowd {crowd!r} replays the raw BIWI tracks, and the data directory {directory} holds no "
            f"raw_ewap/{sequence}/obsmat.txt (a prepared directory keeps only 8 s scenes); set "
            "CROWDMPC_DATA to the folder holding raw_ewap/ (data/README.md)"
        )
    return raw / sequence / "obsmat.txt"


@functools.lru_cache(maxsize=4)
def _read(crowd: str, path: Path, mtime_ns: int) -> Recording:
    """One file's recording, kept while the file is unchanged (``mtime_ns`` is part of the key)."""
    from predictors.data.ewap import infer_frame_step, read_obsmat, split_frames
    from predictors.data.ewap_checks import check_step_seconds

    with_velocities = read_obsmat(path, velocities=True)
    rows = np.ascontiguousarray(with_velocities[:, :4])
    step = infer_frame_step(rows[:, 0])  # of the whole sequence: the test split's gaps must not change it
    # as `data prepare` refuses it: a 10 Hz file replayed its walkers at a quarter of their speed
    check_step_seconds(path, with_velocities, step)
    if crowd.endswith("_test"):
        rows = rows[np.isin(rows[:, 0].astype(np.int64), split_frames(rows[:, 0])["test"])]
    return Recording.from_rows(crowd, rows, step)
