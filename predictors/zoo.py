"""The model zoo: trained predictors as ``state_dict`` + JSON config pairs, listed in ``manifest.json``.

A checkpoint is two files: ``NAME.pt`` (a plain ``state_dict`` of tensors, read with
``torch.load(..., weights_only=True)``, never a pickled object) and ``NAME.json`` (what to build: predictor
class, model kind, net hyper-parameters, observed steps). The manifest (``checkpoints/manifest.json``, or
``$CROWDMPC_CHECKPOINTS/manifest.json``) records for each entry its files and their sha256, the training data
(protocol, files and their hashes) and validation/test metrics. Loading a zoo entry checks both hashes
first; a file that differs is refused with ``CheckpointMismatch``.
"""

from __future__ import annotations

import json
import os
import pickle
import shutil
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from predictors.base import OBS_LEN
from predictors.errors import CheckpointMismatch, PredictorError
from predictors.hashing import sha256_file

if TYPE_CHECKING:
    from predictors.learned import LearnedPredictor
    from predictors.nets.social_lstm import SocialLSTM

CHECKPOINTS_ENV: Final[str] = "CROWDMPC_CHECKPOINTS"
CONFIG_FORMAT: Final[str] = "crowdmpc-predictor"
MANIFEST_FORMAT: Final[str] = "crowdmpc-zoo"
MANIFEST_NAME: Final[str] = "manifest.json"


def checkpoints_dir(directory: str | Path | None = None) -> Path:
    """``directory``, else ``$CROWDMPC_CHECKPOINTS``, else the repository's ``checkpoints/``."""
    if directory is not None:
        return Path(directory)
    env = os.environ.get(CHECKPOINTS_ENV)
    return Path(env) if env else Path(__file__).resolve().parents[1] / "checkpoints"


def read_document(path: Path, document_format: str, what: str) -> dict[str, Any]:
    """A JSON object whose ``"format"`` is ``document_format``, or PredictorError naming ``path``."""
    try:
        document = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise PredictorError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(document, dict) or document.get("format") != document_format:
        raise PredictorError(f'{path}: not a {what} (expected "format": "{document_format}")')
    return document


# ----------------------------------------------------------------------------------------- checkpoint pair
def save_checkpoint(
    net: SocialLSTM, *, model: str, name: str, out_dir: str | Path, obs_len: int, extra: dict | None = None
) -> tuple[Path, Path]:
    """Write ``out_dir/NAME.pt`` (float32 state_dict) and ``out_dir/NAME.json``; returns both paths."""
    import torch

    from predictors.learned import predictor_class_for

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    weights = out_dir / f"{name}.pt"
    config = out_dir / f"{name}.json"
    state = {k: v.detach().to("cpu", torch.float32).clone() for k, v in net.state_dict().items()}
    torch.save(state, weights)
    document = {
        "format": CONFIG_FORMAT,
        "name": name,
        "class": predictor_class_for(model).__name__,
        "model": model,
        "obs_len": obs_len,
        "net": net.config.to_dict(),
        **(extra or {}),
    }
    config.write_text(json.dumps(document, indent=2) + "\n")
    return weights, config


def load_checkpoint(
    weights: str | Path,
    config: str | Path | None = None,
    *,
    name: str | None = None,
    expected_sha256: str | None = None,
    expected_config_sha256: str | None = None,
) -> LearnedPredictor:
    """The predictor of a checkpoint pair (``config`` defaults to ``weights`` with ``.json``)."""
    import torch

    from predictors.learned import PREDICTOR_CLASSES
    from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig

    weights = Path(weights)
    config = Path(config) if config is not None else weights.with_suffix(".json")
    for path, expected in ((weights, expected_sha256), (config, expected_config_sha256)):
        if not path.is_file():
            raise PredictorError(f"checkpoint file {path} does not exist")
        if expected is not None:
            found = sha256_file(path)
            if found != expected:
                raise CheckpointMismatch(path, expected, found)
    document = read_document(config, CONFIG_FORMAT, "crowdmpc predictor config")
    cls_name = document.get("class")
    if cls_name not in PREDICTOR_CLASSES:
        raise PredictorError(
            f"{config}: unknown predictor class {cls_name!r}; expected one of {sorted(PREDICTOR_CLASSES)}"
        )
    obs_len = document.get("obs_len", OBS_LEN)
    if not isinstance(obs_len, int) or isinstance(obs_len, bool):
        raise PredictorError(f'{config}: "obs_len" must be an integer, got {obs_len!r}')
    net = SocialLSTM(SocialLSTMConfig.from_dict(document.get("net", {})))
    try:
        state = torch.load(weights, map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, EOFError, RuntimeError):
        # torch's own message suggests weights_only=False, which a checkpoint must never need
        raise PredictorError(
            f"{weights}: not a state_dict of tensors as `crowdmpc train` writes (truncated, or not a "
            "torch file, or a pickled object, which is never loaded)"
        ) from None
    try:
        net.load_state_dict(state, strict=True)
    except (RuntimeError, KeyError, TypeError, ValueError) as exc:
        raise PredictorError(f"{weights}: weights do not fit the net of {config}: {exc}") from exc
    return PREDICTOR_CLASSES[cls_name](net, name=name or document.get("name", weights.stem), obs_len=obs_len)


# ------------------------------------------------------------------------------------------------ manifest
@dataclass(frozen=True)
class ZooEntry:
    name: str
    cls: str  # predictor class, a key of predictors.learned.PREDICTOR_CLASSES
    model: str  # social_lstm | vanilla_lstm | social_gan
    file: str  # weights file, relative to the checkpoints directory
    sha256: str
    config: str  # JSON config file, relative to the checkpoints directory
    config_sha256: str
    protocol: str  # evaluation protocol of the metrics (paper | loo | synth)
    training_data: dict[str, Any] = field(default_factory=dict)  # files (relative name -> sha256), sha256
    metrics: dict[str, Any] = field(default_factory=dict)  # {"val": {...}, "test": {...}} ADE/FDE [m] ...
    training: dict[str, Any] = field(default_factory=dict)  # epochs, seed, epoch time, command

    def to_json(self) -> dict:
        out = asdict(self)
        return {"name": out.pop("name"), "class": out.pop("cls"), **out}

    @classmethod
    def from_json(cls, values: dict, where: Path) -> ZooEntry:
        if not isinstance(values, dict):
            raise PredictorError(f"{where}: a zoo entry must be a JSON object, got {values!r}")
        required = ("name", "class", "model", "file", "sha256", "config", "config_sha256", "protocol")
        missing = [k for k in required if k not in values]
        if missing:
            raise PredictorError(f"{where}: zoo entry {values.get('name', '?')!r} lacks {missing}")
        values = dict(values)
        values["cls"] = values.pop("class")
        known = set(cls.__dataclass_fields__)
        return cls(**{k: v for k, v in values.items() if k in known})


def read_manifest(directory: str | Path | None = None) -> dict[str, ZooEntry]:
    """Entries by name; an absent manifest is an empty zoo."""
    path = checkpoints_dir(directory) / MANIFEST_NAME
    if not path.is_file():
        return {}
    document = read_document(path, MANIFEST_FORMAT, "crowdmpc zoo manifest")
    models = document.get("models", [])
    if not isinstance(models, list):
        raise PredictorError(f'{path}: "models" must be a list of entries, got {models!r}')
    entries = [ZooEntry.from_json(e, path) for e in models]
    return {e.name: e for e in entries}


def write_manifest(entries: dict[str, ZooEntry], directory: str | Path | None = None) -> Path:
    path = checkpoints_dir(directory) / MANIFEST_NAME
    path.parent.mkdir(parents=True, exist_ok=True)
    document = {
        "format": MANIFEST_FORMAT,
        "version": 1,
        "models": [entries[name].to_json() for name in sorted(entries)],
    }
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(document, indent=2) + "\n")
    tmp.replace(path)
    return path


def zoo_names(directory: str | Path | None = None) -> list[str]:
    return sorted(read_manifest(directory))


def find_entry(name: str, directory: str | Path | None = None) -> ZooEntry:
    entries = read_manifest(directory)
    if name not in entries:
        from predictors.errors import UnknownPredictor

        raise UnknownPredictor(name, sorted(entries))
    return entries[name]


def load_zoo(name: str, directory: str | Path | None = None) -> LearnedPredictor:
    """A zoo entry as a predictor, after checking both files' sha256 against the manifest."""
    root = checkpoints_dir(directory)
    entry = find_entry(name, root)
    return load_checkpoint(
        root / entry.file,
        root / entry.config,
        name=entry.name,
        expected_sha256=entry.sha256,
        expected_config_sha256=entry.config_sha256,
    )


def verify(directory: str | Path | None = None) -> list[tuple[str, str | None]]:
    """``(name, problem or None)`` for every entry: files present, hashes as recorded, weights loadable."""
    root = checkpoints_dir(directory)
    results: list[tuple[str, str | None]] = []
    for name in zoo_names(root):
        try:
            load_zoo(name, root)
            results.append((name, None))
        except PredictorError as exc:
            results.append((name, str(exc)))
    return results


def add_to_zoo(
    weights: str | Path,
    *,
    name: str,
    protocol: str,
    training_data: dict,
    metrics: dict,
    training: dict | None = None,
    directory: str | Path | None = None,
) -> ZooEntry:
    """Copy a checkpoint pair into the zoo as ``NAME.pt``/``NAME.json`` and record it in the manifest."""
    root = checkpoints_dir(directory)
    weights = Path(weights)
    config = weights.with_suffix(".json")
    predictor = load_checkpoint(weights, config)  # refuse a pair that does not load
    document = json.loads(config.read_text())
    document["name"] = name
    root.mkdir(parents=True, exist_ok=True)
    target_weights, target_config = root / f"{name}.pt", root / f"{name}.json"
    if weights.resolve() != target_weights.resolve():
        shutil.copyfile(weights, target_weights)
    target_config.write_text(json.dumps(document, indent=2) + "\n")
    entry = ZooEntry(
        name=name,
        cls=type(predictor).__name__,
        model=document["model"],
        file=target_weights.name,
        sha256=sha256_file(target_weights),
        config=target_config.name,
        config_sha256=sha256_file(target_config),
        protocol=protocol,
        training_data=training_data,
        metrics=metrics,
        training=training or {},
    )
    entries = read_manifest(root)
    entries[name] = entry
    write_manifest(entries, root)
    return entry
