"""A zoo's manifest: ``manifest.json`` lists each model's checkpoint pair (files and their sha256), its
training data and metrics. ``ZooEntry`` checks every value (a manifest is a file anyone can edit) and keeps
every file it names inside the zoo's directory; ``predictors.zoo`` reads the shipped and the user zoo
through it."""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Final

from predictors.checkpoint import check_name, check_sha256, read_document
from predictors.errors import PredictorError, short_repr

MANIFEST_FORMAT: Final[str] = "crowdmpc-zoo"
MANIFEST_NAME: Final[str] = "manifest.json"


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


@dataclass(frozen=True)
class ZooEntry:
    name: str
    cls: str  # predictor class (informational), one of PREDICTOR_CLASS_NAMES
    model: str  # model kind (predictors.models): social_lstm, social_gru, a plugin's module:NetClass ...
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


def read_manifest_at(directory: str | Path) -> dict[str, ZooEntry]:
    """Entries by name of the zoo at ``directory``. An absent manifest is an empty zoo. Every entry is
    checked (``ZooEntry``), and its files must lie inside the zoo directory."""
    root = Path(directory)
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


def write_manifest(entries: dict[str, ZooEntry], directory: str | Path) -> Path:
    """Write the manifest of the zoo at ``directory`` (atomically: a temporary file renamed)."""
    path = Path(directory) / MANIFEST_NAME
    path.parent.mkdir(parents=True, exist_ok=True)
    document = {
        "format": MANIFEST_FORMAT,
        "version": 1,
        "models": [entries[name].to_json() for name in sorted(entries)],
    }
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(document, indent=2) + "\n")
    tmp.replace(path)
    return path
