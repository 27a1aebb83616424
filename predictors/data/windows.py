"""TrajNet++ scenes as training windows: a torch ``Dataset``, the ``SceneBatch`` it collates into, and the
normalisation (centring on the primary, random rotation) that training uses.

Each scene is ``T = obs_len + pred_len`` steps (9 + 12) of all its agents, the primary pedestrian at agent
index 0. Positions are expressed in a scene frame: translated so that the primary's last observed position
(step ``obs_len - 1``) is the origin and, with ``augment``, rotated by an angle drawn uniformly in [0, 2 pi)
-- pedestrian motion has no preferred heading, so rotations are free extra data. Missing entries (an agent
absent at a step) are 0 with ``mask`` False, never NaN.

Loading parses each file once (through ``trajnet_io.scenes_of``, i.e. ``trajnetplusplustools.Reader``)
and keeps the arrays: in memory for the process, and on disk under ``<cache>/scenes/<sha256 of the file>``
(``$CROWDMPC_CACHE`` or ``~/.cache/crowdmpc``) so the next run skips parsing.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import zipfile
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Literal, get_args

import numpy as np
import torch
from torch.utils.data import Dataset, Sampler

from predictors.base import DT, OBS_LEN, PRED_LEN, SCENE_LENGTH, check_steps
from predictors.data.locate import cache_root
from predictors.data.trajnet_io import last_steps, shown_scenes
from predictors.data.validate import NdjsonContent, parse_ndjson, read_error, require_file
from predictors.errors import PredictorError
from predictors.hashing import sha256_file

CACHE_VERSION: Final[str] = "scenes-v4"  # bump when FileArrays' layout or the validation changes


@dataclass(frozen=True)
class FileArrays:
    """All scenes of one file, agents of every scene concatenated along one axis."""

    xy: (
        np.ndarray
    )  # (T, A, 2) float32 metres, world frame, NaN where an agent is absent; A = agents of all scenes
    offsets: np.ndarray  # (S + 1,) int64: scene s owns agents offsets[s]:offsets[s+1], its primary first
    scene_ids: np.ndarray  # (S,) int64 scene ids as in the file

    def __len__(self) -> int:
        return len(self.scene_ids)

    def scene(self, s: int) -> np.ndarray:
        """``(T, N_s, 2)`` positions of scene ``s``."""
        return self.xy[:, self.offsets[s] : self.offsets[s + 1]]


# How a file's scenes become windows (load_file_arrays): training's exact scenes, or each scene's end.
Window = Literal["whole", "last"]
WINDOWS: Final[tuple[str, ...]] = get_args(Window)

_MEMORY: dict[tuple[str, int, int, int, str], FileArrays] = {}


def _remember(key: tuple[str, int, int, int, str], arrays: FileArrays) -> FileArrays:
    """``arrays`` kept for ``key``, in place of any earlier version of the same file at the same scene
    length and window: a long-lived process that rewrites its data (a notebook) would otherwise hold every
    version."""
    for old in [k for k in _MEMORY if (k[0], k[3], k[4]) == (key[0], key[3], key[4])]:
        del _MEMORY[old]
    _MEMORY[key] = arrays
    return arrays


def load_file_arrays(
    path: str | Path,
    *,
    scene_length: int = SCENE_LENGTH,
    window: Window = "whole",
    disk_cache: bool = True,
    progress: bool | None = False,
    content: NdjsonContent | None = None,
) -> FileArrays:
    """The scenes of ``path`` as arrays of ``scene_length`` steps. ``window`` "whole": every primary must
    span exactly that many evenly spaced frames (training's windows); "last": each scene's last
    ``scene_length`` frames, evenly spaced, of a scene at least that long, as the evaluation reads it
    (``predictors.evaluate``; validation and test). ``progress``: a bar over the scenes while they are
    built (None: on a terminal only); a cached file has none to show. Building costs time in scenes x
    agents: a file of dense crowds takes a minute. ``content``: ``path`` as ``parse_ndjson`` read it, when
    the caller has parsed it already (``crowdmpc train`` evaluates its validation files too): built from,
    not parsed again."""
    if window not in WINDOWS:
        raise PredictorError(f"window must be one of {list(WINDOWS)}, got {window!r}")
    path = require_file(path)
    try:
        stat = path.stat()
        key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns, scene_length, window)
        if key in _MEMORY:
            return _MEMORY[key]
        digest = sha256_file(path) if disk_cache else None
    except OSError as exc:
        raise read_error(path, None, exc) from None
    disk = None
    if disk_cache:
        mode = "" if window == "whole" else f"{window}-"  # the whole scenes' entries keep their names
        disk = cache_root() / "scenes" / f"{digest}-{scene_length}-{mode}{CACHE_VERSION}.npz"
        arrays = _load_entry(disk, scene_length)
        if arrays is not None:
            return _remember(key, arrays)
    # a scene at a time, kept as float32: the float64 scenes of a large file are several times its arrays
    xys, ids = [np.empty((scene_length, 0, 2), dtype=np.float32)], []
    content = parse_ndjson(path) if content is None else content
    whole = {"require_length": scene_length} if window == "whole" else {}
    needs = f"validation and test read the last {scene_length}, as the evaluation does"
    for scene in shown_scenes(content, progress, require_fps=1 / DT, **whole):
        if window == "last":
            scene = last_steps(scene, scene_length, path, needs)
        xys.append(scene.xy.astype(np.float32))
        ids.append(scene.id)
    sizes = np.asarray([xy.shape[1] for xy in xys[1:]], dtype=np.int64)
    arrays = FileArrays(
        xy=np.concatenate(xys, axis=1),
        offsets=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        scene_ids=np.asarray(ids, dtype=np.int64),
    )
    if disk is not None:
        _store_entry(disk, arrays)
    return _remember(key, arrays)


# What reading a damaged .npz raises (found by garbling and cutting an entry): a cut or garbled zip
# (BadZipFile, EOFError), a bad CRC or npy header (BadZipFile, ValueError), a missing array (KeyError), a
# garbled compression method or encryption flag (NotImplementedError, RuntimeError), a member that does not
# inflate (zlib.error).
_DAMAGED_ENTRY: Final = (
    OSError,
    KeyError,
    ValueError,
    EOFError,
    NotImplementedError,
    RuntimeError,
    zipfile.BadZipFile,
    zlib.error,
)


def _load_entry(disk: Path, scene_length: int) -> FileArrays | None:
    """The arrays of a disk cache entry, or None when there is none or it is damaged (rebuilt by the
    caller): a crash, a full disk or another tool can leave any bytes there."""
    if not disk.is_file():
        return None
    try:
        with np.load(disk) as data:
            arrays = FileArrays(data["xy"], data["offsets"], data["scene_ids"])
    except _DAMAGED_ENTRY:
        return None
    xy, offsets, scene_ids = arrays.xy, arrays.offsets, arrays.scene_ids
    whole = (
        xy.ndim == 3
        and xy.shape[0] == scene_length
        and xy.shape[2] == 2
        and scene_ids.ndim == 1
        and offsets.shape == (scene_ids.size + 1,)
        and offsets.dtype.kind in "iu"
        and offsets[0] == 0
        and bool(np.all(np.diff(offsets) >= 0))
        and offsets[-1] == xy.shape[1]
    )
    return arrays if whole else None


def _store_entry(disk: Path, arrays: FileArrays) -> None:
    """Writes the entry through a temporary file of this process's own, renamed into place: runs sharing
    the cache (data loader workers, parallel trainings) each write their own file, where one shared name let
    one run rename another's half-written file into place, and a reader sees a whole entry or none."""
    tmp = disk.with_name(f".{disk.name}.{os.getpid()}.tmp")
    try:
        disk.parent.mkdir(parents=True, exist_ok=True)
        with tmp.open("wb") as handle:  # a file object: np.savez would append .npz to a name
            np.savez(handle, xy=arrays.xy, offsets=arrays.offsets, scene_ids=arrays.scene_ids)
        tmp.replace(disk)
    except OSError:  # a read-only or full cache only costs speed
        pass
    finally:  # a write that failed, or a Ctrl-C in it, leaves no temporary (nothing else removes it)
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)


@dataclass(frozen=True)
class SceneSample:
    """One normalised scene (what ``TrajnetSceneDataset[i]`` returns)."""

    positions: np.ndarray  # (T, N, 2) float32, scene frame, 0 where mask is False
    mask: np.ndarray  # (T, N) bool
    origin: np.ndarray  # (2,) float32, world position of the scene-frame origin
    rotation: np.ndarray  # (2, 2) float32, scene = (world - origin) @ rotation.T


@dataclass
class SceneBatch:
    """A padded batch of scenes; agent 0 of every scene is its primary pedestrian.

    Not frozen: Lightning's precision plugins (``Trainer(precision="64-true")``) and device moves rebuild a
    batch field by field with ``apply_to_collection``, which refuses a frozen dataclass."""

    positions: torch.Tensor  # (B, T, Nmax, 2) float32 metres, scene frame, 0 where mask is False
    mask: torch.Tensor  # (B, T, Nmax) bool, True where the agent is present (False also for padding)
    origin: torch.Tensor  # (B, 2) float32, world position of each scene's origin (primary at step obs_len-1)
    rotation: torch.Tensor  # (B, 2, 2) float32, positions = (world - origin) @ rotation^T
    obs_len: int  # steps [0, obs_len) are observed, [obs_len, T) are to be predicted

    def __len__(self) -> int:
        return self.positions.shape[0]

    @property
    def observed(self) -> torch.Tensor:
        """(B, obs_len, Nmax, 2)"""
        return self.positions[:, : self.obs_len]

    @property
    def future(self) -> torch.Tensor:
        """(B, T - obs_len, Nmax, 2)"""
        return self.positions[:, self.obs_len :]

    def to_world(self, positions: torch.Tensor) -> torch.Tensor:
        """Scene-frame positions ``(B, ..., 2)`` back to world coordinates."""
        flat = positions.reshape(positions.shape[0], -1, 2)
        world = flat @ self.rotation + self.origin[:, None, :]
        return world.reshape(positions.shape)

    def to(self, device, non_blocking: bool = False) -> SceneBatch:
        """A copy on ``device`` (Lightning moves batches through this method)."""
        return dataclasses.replace(
            self,
            **{
                f.name: getattr(self, f.name).to(device, non_blocking=non_blocking)
                for f in dataclasses.fields(self)
                if isinstance(getattr(self, f.name), torch.Tensor)
            },
        )


def rotation_matrix(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.asarray([[c, -s], [s, c]], dtype=np.float32)


def normalise(xy: np.ndarray, obs_len: int, angle: float | None, *, where: str | None = None) -> SceneSample:
    """Centre ``xy`` ``(T, N, 2)`` (NaN = absent) on the primary's position at step ``obs_len - 1`` and rotate
    by ``angle`` (radians, counter-clockwise; None = no rotation). ``where`` (e.g. the file and scene) starts
    the error message."""
    mask = ~np.isnan(xy).any(axis=-1)
    if not mask[obs_len - 1, 0]:
        seen = np.flatnonzero(mask[:obs_len, 0]).tolist()
        raise PredictorError(
            f"{where + ': ' if where else ''}the primary pedestrian (agent 0) must be present at the last "
            f"observed step {obs_len - 1}; it is absent there (observed at steps {seen} of 0..{obs_len - 1})"
        )
    origin = xy[obs_len - 1, 0].astype(np.float32)
    rotation = rotation_matrix(angle) if angle is not None else np.eye(2, dtype=np.float32)
    positions = (np.where(mask[..., None], xy, origin) - origin) @ rotation.T
    positions = np.where(mask[..., None], positions, 0.0).astype(np.float32)
    return SceneSample(positions, mask, origin, rotation)


def path_list(files: Iterable[str | Path], what: str) -> list[str | Path]:
    """``files`` as a list; one path given alone (``what``: the argument, e.g. "train_files") is refused in
    one line, since a str is a sequence of its letters, which were read as files ("/: is a directory, not a
    data file"), and a Path is no sequence at all."""
    if isinstance(files, (str, Path)):
        raise PredictorError(f"{what} is a list of paths, got the single path {str(files)!r}: write [path]")
    return list(files)


class TrajnetSceneDataset(Dataset):
    """Scenes of one or more TrajNet++ files as normalised ``SceneSample``s.

    With ``augment`` every item is rotated by a random angle, a function of ``(seed, epoch, index)``: the
    item ``dataset[index, epoch]`` (what ``EpochShuffle`` hands a loader) or ``dataset[index]`` (epoch 0). So
    the angles are the same in worker processes and in a run resumed at that epoch, and new in every epoch.
    (They used to come from one generator drawn item after item, which a resumed run restarted: its first
    epoch repeated epoch 0's angles.) ``window``: how the files' scenes are read (``load_file_arrays``).
    """

    def __init__(
        self,
        files: list[str | Path],
        *,
        obs_len: int = OBS_LEN,
        pred_len: int = PRED_LEN,
        augment: bool = False,
        seed: int = 0,
        scene_length: int = SCENE_LENGTH,
        window: Window = "whole",
    ):
        check_steps(obs_len, pred_len, "a scene dataset")
        if obs_len + pred_len > scene_length:
            raise PredictorError(
                f"a scene dataset: need obs_len + pred_len <= {scene_length} (the scenes' steps), "
                f"got obs_len={obs_len}, pred_len={pred_len}"
            )
        self.files = [Path(f) for f in path_list(files, "files")]
        if not self.files:
            raise PredictorError("a scene dataset needs at least one file")
        self.obs_len = obs_len
        self.pred_len = pred_len
        self.augment = augment
        self.arrays = [load_file_arrays(f, scene_length=scene_length, window=window) for f in self.files]
        sizes = np.asarray([len(a) for a in self.arrays], dtype=np.int64)
        self._starts = np.concatenate([[0], np.cumsum(sizes)])
        self.seed = seed

    def __len__(self) -> int:
        return int(self._starts[-1])

    def locate(self, index: int) -> tuple[int, int]:
        """(file index, scene index within that file) of dataset item ``index``."""
        if not 0 <= index < len(self):
            raise IndexError(index)
        k = int(np.searchsorted(self._starts, index, side="right") - 1)
        return k, int(index - self._starts[k])

    def agent_counts(self) -> np.ndarray:
        """(len,) int64: the agents of every item as ``__getitem__`` returns it (those present somewhere in
        the window, the primary always), without normalising any scene: what a batch pads to its largest."""
        steps = self.obs_len + self.pred_len
        counts = []
        for arrays in self.arrays:
            window = arrays.xy[arrays.xy.shape[0] - steps :]
            present = ~np.isnan(window).any(axis=-1).all(axis=0)
            starts, ends = arrays.offsets[:-1], arrays.offsets[1:]
            present[starts[ends > starts]] = True
            total = np.concatenate([[0], np.cumsum(present, dtype=np.int64)])
            counts.append(total[ends] - total[starts])
        return np.concatenate(counts) if counts else np.zeros(0, dtype=np.int64)

    def _angle(self, index: int, epoch: int) -> float:
        return float(np.random.default_rng([self.seed, epoch, index]).random()) * 2.0 * math.pi

    def __getitem__(self, key: int | tuple[int, int]) -> SceneSample:
        index, epoch = key if isinstance(key, tuple) else (key, 0)
        k, s = self.locate(index)
        xy = self.arrays[k].scene(s)
        xy = xy[xy.shape[0] - (self.obs_len + self.pred_len) :]  # the prediction is always the scene's end
        present = ~np.isnan(xy).any(axis=-1).all(axis=0)  # drop agents absent from the whole window
        present[0] = True
        return normalise(
            xy[:, present],
            self.obs_len,
            self._angle(index, epoch) if self.augment else None,
            where=f"{self.files[k]}: scene {int(self.arrays[k].scene_ids[s])}",
        )


class EpochShuffle(Sampler[tuple[int, int]]):
    """A new order of ``dataset``'s items every epoch, a function of ``(seed, epoch)`` as in torch's
    ``DistributedSampler``, each item keyed ``(index, epoch)`` for its rotation (``TrajnetSceneDataset``).
    Lightning calls ``set_epoch`` as each epoch starts, after restoring a checkpoint's epoch, so a resumed
    run shuffles and rotates as an uninterrupted one does. Outside Lightning, call ``set_epoch`` before each
    epoch, as for torch's sampler."""

    def __init__(self, dataset: TrajnetSceneDataset, seed: int = 0):
        self.size = len(dataset)
        self.seed = seed
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __len__(self) -> int:
        return self.size

    def __iter__(self) -> Iterator[tuple[int, int]]:
        order = np.random.default_rng([self.seed, self.epoch]).permutation(self.size)
        return ((int(i), self.epoch) for i in order)


def collate_scenes(samples: list[SceneSample], obs_len: int = OBS_LEN) -> SceneBatch:
    """Pad the agents of ``samples`` to the batch maximum and stack them into a ``SceneBatch``."""
    steps = samples[0].positions.shape[0]
    n_max = max(s.positions.shape[1] for s in samples)
    positions = np.zeros((len(samples), steps, n_max, 2), dtype=np.float32)
    mask = np.zeros((len(samples), steps, n_max), dtype=bool)
    for b, sample in enumerate(samples):
        n = sample.positions.shape[1]
        positions[b, :, :n] = sample.positions
        mask[b, :, :n] = sample.mask
    return SceneBatch(
        positions=torch.from_numpy(positions),
        mask=torch.from_numpy(mask),
        origin=torch.from_numpy(np.stack([s.origin for s in samples])),
        rotation=torch.from_numpy(np.stack([s.rotation for s in samples])),
        obs_len=obs_len,
    )
