"""The real-data source of calibration: a predictor's step-wise displacement errors on TrajNet++ scenes (where
it was trained, so no simulator is needed), and the hashes that identify those scenes in a block's
``data_sha256``.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Final

import numpy as np

from crowdsim import world
from predictors.base import Predictor
from predictors.errors import PredictorError
from predictors.evaluate import EvalConfig, EvalScene, load_eval_scenes, predict_scene
from predictors.hashing import sha256_file

HORIZON: Final[int] = world.HORIZON  # MPC horizon steps H the margins are made for by default


def validation_files(data_dir: str | Path | None = None) -> list[Path]:
    """The prepared data's ``val/`` ndjson files (biwi_eth, biwi_hotel: the paper protocol's val split).

    Their names relative to ``predictors.data.locate.prepared_dir(data_dir)`` are what ``real_data_sha256``
    should hash (pass that directory as ``root``).
    """
    from predictors.data.locate import protocol_files

    return protocol_files(data_dir, "paper")["val"]


def file_hashes(files: list[Path], root: str | Path | None = None) -> dict[str, str]:
    """``{name: sha256}``; names relative to ``root`` where inside it, else the bare file name."""
    root = Path(root) if root is not None else None
    hashes: dict[str, str] = {}
    for path in map(Path, files):
        if root is not None and path.is_relative_to(root):
            name = path.relative_to(root).as_posix()
        else:
            name = path.name
        if name in hashes:
            raise PredictorError(
                f"two calibration files are both named {name!r} ({path}); pass the data directory as root "
                "so that their relative names tell them apart"
            )
        hashes[name] = sha256_file(path)
    return hashes


def combined_sha256(hashes: dict[str, str]) -> str:
    """One sha256 over ``{name: sha256}`` sorted by name, so the order files were given in does not matter."""
    digest = hashlib.sha256()
    for name, sha in sorted(hashes.items()):
        digest.update(f"{name}:{sha}\n".encode())
    return digest.hexdigest()


def real_data_sha256(files: list[Path], root: str | Path | None = None) -> str:
    """One sha256 over the sorted file names (see ``file_hashes``) and their contents' sha256."""
    return combined_sha256(file_hashes(files, root))


def _scene_errors(predictor: Predictor, scene: EvalScene, config: EvalConfig) -> tuple[np.ndarray, list]:
    """Rows ``(m, H)`` for the agents observed at the last observed step, and their (frame, x, y) keys."""
    prediction, agents, _ = predict_scene(predictor, scene.xy, config, None)
    last = config.obs_len - 1
    now = scene.xy[last, agents]
    current = ~np.isnan(now).any(axis=-1)  # a predictor only knows where someone is now if it saw them now
    truth = scene.xy[config.obs_len :, agents]
    errors = np.linalg.norm(prediction - truth, axis=-1)  # NaN where the agent is absent at step k
    frame = int(scene.frames[last])
    keys = [(frame, float(x), float(y)) for x, y in now[current]]
    return errors[:, current].T, keys


def real_errors(predictor: Predictor, files: list[Path], horizon: int = HORIZON) -> np.ndarray:
    """Step-wise displacement errors ``(n, horizon)`` of ``predictor`` on TrajNet++ ndjson ``files``.

    Each scene is cut to its last ``predictor.obs_len + horizon`` steps (``load_eval_scenes``) and predicted
    with every agent as a human and no robots (``predict_scene``). TrajNet++ scenes overlap: the same person
    at the same time appears in the scene of each nearby primary. A row is one (person, prediction time), so
    within a file a repeat (same last observed frame and position) is dropped and the first scene's
    prediction is kept.
    """
    if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
        raise PredictorError(f"horizon must be a positive number of steps, got {horizon!r}")
    config = EvalConfig(obs_len=predictor.obs_len, pred_len=horizon)
    rows: list[np.ndarray] = []
    for path in files:
        seen: set[tuple[int, float, float]] = set()
        for scene in load_eval_scenes(path, config):
            errors, keys = _scene_errors(predictor, scene, config)
            for row, key in zip(errors, keys, strict=True):
                if key not in seen:
                    seen.add(key)
                    rows.append(row)
    return np.asarray(rows, dtype=float).reshape(-1, horizon)
