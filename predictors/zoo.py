"""The model zoo: trained predictors as ``state_dict`` + JSON config pairs, listed in ``manifest.json``.

A checkpoint is two files: ``NAME.pt`` (a plain ``state_dict`` of tensors, read with
``torch.load(..., weights_only=True)``, never a pickled object) and ``NAME.json`` (what to build: predictor
class, model kind, net hyper-parameters, observed steps). The manifest (``checkpoints/manifest.json``, or
``$CROWDMPC_CHECKPOINTS/manifest.json``) records for each entry its files and their sha256, the training data
(protocol, files and their hashes) and validation/test metrics. Loading a zoo entry checks both hashes
first; a file that differs is refused with ``CheckpointMismatch``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from predictors.base import OBS_LEN
from predictors.errors import CheckpointMismatch, PredictorError, short_repr
from predictors.hashing import sha256_file

if TYPE_CHECKING:
    from predictors.learned import LearnedPredictor
    from predictors.nets.social_lstm import SocialLSTM

CHECKPOINTS_ENV: Final[str] = "CROWDMPC_CHECKPOINTS"
CONFIG_FORMAT: Final[str] = "crowdmpc-predictor"
MANIFEST_FORMAT: Final[str] = "crowdmpc-zoo"
MANIFEST_NAME: Final[str] = "manifest.json"

# A zoo name becomes a file name (NAME.pt, NAME.json) and a CasADi function name: letters, digits, "_", "."
# and "-", starting with a letter or digit, so that no name is a path ("../x", "/tmp/x"), hidden, "." or "..".
NAME_PATTERN: Final[re.Pattern[str]] = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
SHA256_PATTERN: Final[re.Pattern[str]] = re.compile(r"[0-9a-f]{64}")
# Observed steps a checkpoint may ask for: TrajNet++ observes 9 (3.6 s at 2.5 Hz); 100 steps are 40 s of
# history, beyond any scene's, and the encoder (torch and CasADi) unrolls once per step.
MAX_OBS_LEN: Final[int] = 100
# A manifest or config is a few kB (the shipped manifest 13 kB); refuse to read a huge file into memory.
MAX_DOCUMENT_BYTES: Final[int] = 64 << 20
# A weights file holds the net's tensors (at most 8 bytes an element, float64) plus torch's zip framing.
WEIGHTS_OVERHEAD_BYTES: Final[int] = 1 << 20


def check_name(name: object, what: str = "zoo name") -> str:
    """``name`` if it is a safe zoo name (``NAME_PATTERN``), else PredictorError."""
    if not isinstance(name, str) or NAME_PATTERN.fullmatch(name) is None:
        raise PredictorError(
            f"{what} {short_repr(name)} is not allowed: use 1 to 64 letters, digits, '_', '.' or '-', "
            "starting with a letter or digit"
        )
    return name


def check_sha256(value: object, what: str) -> str:
    """``value`` if it is a sha256 as the zoo records it (64 lowercase hex digits), else PredictorError.

    A missing hash is never "skip the check": every zoo file is verified before it is loaded."""
    if not isinstance(value, str) or SHA256_PATTERN.fullmatch(value) is None:
        raise PredictorError(f"{what} must be a sha256 (64 lowercase hex digits), got {short_repr(value)}")
    return value


def zoo_path(root: Path, relative: object, what: str) -> Path:
    """``root / relative`` resolved (symbolic links followed), or PredictorError (naming ``what``) when it is
    not a relative path that stays inside ``root``."""
    if not isinstance(relative, str) or not relative or "\x00" in relative:
        raise PredictorError(f"{what} must be a file name inside the zoo, got {short_repr(relative)}")
    try:
        base = root.resolve()
        resolved = (root / relative).resolve()
    except (OSError, RuntimeError, ValueError) as exc:  # a symlink loop, an unreadable directory
        raise PredictorError(f"{what} {short_repr(relative)} cannot be resolved: {exc}") from None
    if resolved == base or not resolved.is_relative_to(base):
        raise PredictorError(f"{what} {short_repr(relative)} lies outside the zoo directory {base}")
    return resolved


def checkpoints_dir(directory: str | Path | None = None) -> Path:
    """``directory``, else ``$CROWDMPC_CHECKPOINTS``, else the repository's ``checkpoints/``."""
    if directory is not None:
        return Path(directory)
    env = os.environ.get(CHECKPOINTS_ENV)
    return Path(env) if env else Path(__file__).resolve().parents[1] / "checkpoints"


def read_document(path: Path, document_format: str, what: str) -> dict[str, Any]:
    """A JSON object whose ``"format"`` is ``document_format``, or PredictorError naming ``path``."""
    if path.exists() and not path.is_file():  # a directory or a FIFO (reading one would block forever)
        raise PredictorError(f"{path}: not a regular file")
    size = path.stat().st_size  # a missing file: FileNotFoundError, as before
    if size > MAX_DOCUMENT_BYTES:
        raise PredictorError(f"{path}: {size} bytes, more than the {MAX_DOCUMENT_BYTES} a {what} may have")
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise PredictorError(f"{path}: not valid JSON (not UTF-8 text)") from None
    except ValueError as exc:  # JSONDecodeError, or an integer literal of more than 4300 digits
        raise PredictorError(f"{path}: not valid JSON ({exc})") from None
    except RecursionError:
        raise PredictorError(f"{path}: not valid JSON (nested too deeply)") from None
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
    """The predictor of a checkpoint pair (``config`` defaults to ``weights`` with ``.json``).

    Everything is checked before it is used, each failure a PredictorError naming the file: the sha256 (when
    expected, as the zoo always does), the config's types and ranges before any net is built, the weights'
    size before they are read, then that they are a state_dict of finite float tensors of the net's shapes.
    """
    import torch

    from predictors.learned import MODEL_KINDS, PREDICTOR_CLASSES, predictor_class_for
    from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig

    weights = Path(weights)
    config = Path(config) if config is not None else weights.with_suffix(".json")
    for path, expected in ((weights, expected_sha256), (config, expected_config_sha256)):
        if not path.exists():
            raise PredictorError(f"checkpoint file {path} does not exist")
        if not path.is_file():
            raise PredictorError(f"checkpoint file {path} is not a regular file")
        if expected is not None:
            found = sha256_file(path)
            if found != check_sha256(expected, f"the expected sha256 of {path}"):
                raise CheckpointMismatch(path, expected, found)
    document = read_document(config, CONFIG_FORMAT, "crowdmpc predictor config")
    cls_name = document.get("class")
    if not isinstance(cls_name, str) or cls_name not in PREDICTOR_CLASSES:
        raise PredictorError(
            f"{config}: unknown predictor class {short_repr(cls_name)}; expected one of "
            f"{sorted(PREDICTOR_CLASSES)}"
        )
    model = document.get("model")
    if model is not None:
        if not isinstance(model, str) or model not in MODEL_KINDS:
            raise PredictorError(
                f'{config}: "model" must be one of {list(MODEL_KINDS)}, got {short_repr(model)}'
            )
        if predictor_class_for(model).__name__ != cls_name:
            raise PredictorError(f'{config}: "model" {model!r} does not go with "class" {cls_name!r}')
    own_name = document.get("name", weights.stem)
    if not isinstance(own_name, str):
        raise PredictorError(f'{config}: "name" must be a string, got {short_repr(own_name)}')
    obs_len = document.get("obs_len", OBS_LEN)
    if isinstance(obs_len, bool) or not isinstance(obs_len, int):
        raise PredictorError(f'{config}: "obs_len" must be an integer, got {short_repr(obs_len)}')
    if not 2 <= obs_len <= MAX_OBS_LEN:
        raise PredictorError(f'{config}: "obs_len" must be in 2..{MAX_OBS_LEN}, got {obs_len}')
    try:
        net_config = SocialLSTMConfig.from_dict(document.get("net", {}))
    except PredictorError as exc:
        raise PredictorError(f'{config}: "net": {exc}') from None
    net = SocialLSTM(net_config)  # bounded: the config's checks cap its parameters
    expected_state = net.state_dict()
    limit = 8 * sum(t.numel() for t in expected_state.values()) + WEIGHTS_OVERHEAD_BYTES
    size = weights.stat().st_size
    if size > limit:
        raise PredictorError(
            f"{weights}: {size} bytes, more than the {limit} a state_dict of the net of {config} can take"
        )
    try:
        state = torch.load(weights, map_location="cpu", weights_only=True)
    except Exception:  # whatever a corrupt or hostile file makes torch raise, the file is at fault
        # torch's own message suggests weights_only=False, which a checkpoint must never need
        raise PredictorError(
            f"{weights}: not a state_dict of tensors as `crowdmpc train` writes (truncated, or not a "
            "torch file, or a pickled object, which is never loaded)"
        ) from None
    check_state_dict(state, expected_state, weights, config)
    try:
        net.load_state_dict(state, strict=True)
    except (RuntimeError, KeyError, TypeError, ValueError) as exc:  # not expected after the checks above
        raise PredictorError(f"{weights}: weights do not fit the net of {config}: {exc}") from None
    try:
        return PREDICTOR_CLASSES[cls_name](net, name=name or own_name, obs_len=obs_len)
    except PredictorError as exc:
        raise PredictorError(f"{config}: {exc}") from None


def check_state_dict(state: object, expected: dict[str, Any], weights: Path, config: Path) -> None:
    """PredictorError (one line, naming ``weights``) unless ``state`` holds exactly the tensors of
    ``expected`` (a net's ``state_dict``), each of its shape, floating point and finite."""
    import torch

    if not isinstance(state, dict):
        raise PredictorError(f"{weights}: not a state_dict (a dict of tensors), but a {type(state).__name__}")
    for key, value in state.items():
        if not isinstance(key, str):
            raise PredictorError(f"{weights}: a state_dict key is {short_repr(key)}, not a string")
        if not isinstance(value, torch.Tensor) or value.layout != torch.strided or value.is_quantized:
            raise PredictorError(
                f"{weights}: {short_repr(key)} is a {type(value).__name__}, not a dense tensor"
            )
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    if missing or unexpected:
        raise PredictorError(
            f"{weights}: weights do not fit the net of {config}: missing {short_repr(missing, 120)}, "
            f"unexpected {short_repr(unexpected, 120)}"
        )
    for key, value in state.items():
        want = tuple(expected[key].shape)
        if tuple(value.shape) != want:
            raise PredictorError(
                f"{weights}: tensor {key!r} has shape {tuple(value.shape)}, the net of {config} needs {want}"
            )
        if not value.is_floating_point():
            raise PredictorError(f"{weights}: tensor {key!r} is {value.dtype}, not floating point")
        if not bool(torch.isfinite(value).all()):
            raise PredictorError(f"{weights}: tensor {key!r} holds NaN or infinite values")


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

    def __post_init__(self):
        """Every value checked: a manifest is a file anyone can edit, and the zoo trusts nothing in it."""
        check_name(self.name)
        where = f"entry {self.name!r}:"
        for key, value in (("class", self.cls), ("model", self.model), ("protocol", self.protocol)):
            if not isinstance(value, str):
                raise PredictorError(f'{where} "{key}" must be a string, got {short_repr(value)}')
        for key, value in (("file", self.file), ("config", self.config)):
            if not isinstance(value, str) or not value or "\x00" in value:
                raise PredictorError(
                    f'{where} "{key}" must be a file name inside the zoo, got {short_repr(value)}'
                )
        check_sha256(self.sha256, f'{where} "sha256"')
        check_sha256(self.config_sha256, f'{where} "config_sha256"')
        for key in ("training_data", "metrics", "training"):
            if not isinstance(getattr(self, key), dict):
                raise PredictorError(
                    f'{where} "{key}" must be a JSON object, got {short_repr(getattr(self, key))}'
                )

    def to_json(self) -> dict:
        out = asdict(self)
        return {"name": out.pop("name"), "class": out.pop("cls"), **out}

    @classmethod
    def from_json(cls, values: dict, where: Path) -> ZooEntry:
        if not isinstance(values, dict):
            raise PredictorError(f"{where}: a zoo entry must be a JSON object, got {short_repr(values)}")
        required = ("name", "class", "model", "file", "sha256", "config", "config_sha256", "protocol")
        missing = [k for k in required if k not in values]
        if missing:
            raise PredictorError(f"{where}: zoo entry {short_repr(values.get('name', '?'))} lacks {missing}")
        values = dict(values)
        values["cls"] = values.pop("class")
        known = set(cls.__dataclass_fields__)
        try:
            return cls(**{k: v for k, v in values.items() if k in known})
        except PredictorError as exc:
            raise PredictorError(f"{where}: {exc}") from None

    def paths(self, root: Path, where: Path | str) -> tuple[Path, Path]:
        """The weights and config files, resolved; PredictorError naming ``where`` (the manifest) and the key
        when one lies outside the zoo directory ``root``."""
        return (
            zoo_path(root, self.file, f'{where}: entry {self.name!r}: "file"'),
            zoo_path(root, self.config, f'{where}: entry {self.name!r}: "config"'),
        )


def read_manifest(directory: str | Path | None = None) -> dict[str, ZooEntry]:
    """Entries by name; an absent manifest is an empty zoo. Every entry is checked (``ZooEntry``), and its
    files must lie inside the zoo directory."""
    root = checkpoints_dir(directory)
    path = root / MANIFEST_NAME
    if not path.exists() and not path.is_symlink():
        return {}
    if not path.is_file():  # a directory, a FIFO, a dangling link: never "an empty zoo"
        raise PredictorError(f"{path}: the zoo manifest is not a regular file")
    document = read_document(path, MANIFEST_FORMAT, "crowdmpc zoo manifest")
    models = document.get("models", [])
    if not isinstance(models, list):
        raise PredictorError(f'{path}: "models" must be a list of entries, got {short_repr(models)}')
    entries: dict[str, ZooEntry] = {}
    for values in models:
        entry = ZooEntry.from_json(values, path)
        if entry.name in entries:
            raise PredictorError(f"{path}: entry {entry.name!r} appears twice")
        entry.paths(root, path)
        entries[entry.name] = entry
    return entries


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
    weights, config = entry.paths(root, root / MANIFEST_NAME)
    return load_checkpoint(
        weights,
        config,
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
    check_name(name)  # before anything is written: NAME becomes the files' names
    root = checkpoints_dir(directory)
    weights = Path(weights)
    config = weights.with_suffix(".json")
    entries = read_manifest(root)  # refuse to add to a manifest that does not read
    predictor = load_checkpoint(weights, config)  # refuse a pair that does not load
    document = read_document(config, CONFIG_FORMAT, "crowdmpc predictor config")
    if "model" not in document:
        raise PredictorError(f'{config}: "model" is missing; `crowdmpc train` writes it')
    document["name"] = name
    config_bytes = (json.dumps(document, indent=2) + "\n").encode()
    entry = ZooEntry(  # checked (name, protocol, metrics ...) before anything is written
        name=name,
        cls=type(predictor).__name__,
        model=document["model"],
        file=f"{name}.pt",
        sha256=sha256_file(weights),
        config=f"{name}.json",
        config_sha256=hashlib.sha256(config_bytes).hexdigest(),
        protocol=protocol,
        training_data=training_data,
        metrics=metrics,
        training=training or {},
    )
    root.mkdir(parents=True, exist_ok=True)
    # resolved: a symbolic link NAME.pt in the zoo must not make us write elsewhere
    target_weights, target_config = entry.paths(root, root / MANIFEST_NAME)
    if weights.resolve() != target_weights:
        shutil.copyfile(weights, target_weights)
    target_config.write_bytes(config_bytes)
    entry = replace(entry, sha256=sha256_file(target_weights))  # the copy's, should the source have changed
    entries[name] = entry
    write_manifest(entries, root)
    return entry
