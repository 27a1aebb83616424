"""A zoo's manifest: ``manifest.json`` lists each model's checkpoint pair (files and their sha256), its
training data and metrics. ``ZooEntry`` checks every value (a manifest is a file anyone can edit) and keeps
every file it names inside the zoo's directory; ``predictors.zoo`` reads the shipped and the user zoo
through it. Besides its models' pairs a zoo keeps files of its own (``ZOO_FILES``), which no model may take
the name of, and a lock (``zoo_lock``) that serialises the writers of its manifest."""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Final

from predictors.checkpoint import check_name, check_sha256, read_document
from predictors.durable import write_text_durably
from predictors.errors import PredictorError, short_repr
from predictors.locking import locked

MANIFEST_FORMAT: Final[str] = "crowdmpc-zoo"
MANIFEST_NAME: Final[str] = "manifest.json"
MANIFEST_VERSION: Final[int] = 1  # the layout write_manifest writes, and the newest read_manifest_at reads
CALIBRATIONS_NAME: Final[str] = "calibrations.json"  # predictors.calibration's blocks, beside the manifest
LOCK_NAME: Final[str] = ".zoo.lock"  # hidden: NAME_PATTERN names never start with "."
# The files a zoo keeps besides its models' pairs, and what each holds: a model's NAME.pt / NAME.json must
# never be written over one of them, nor one be deleted as a model's file.
ZOO_FILES: Final[dict[str, str]] = {
    MANIFEST_NAME: "manifest (the list of its models)",
    CALIBRATIONS_NAME: "conformal calibrations (kept by `crowdmpc calibrate`)",
    LOCK_NAME: "lock file",
}


def zoo_file(file_name: str) -> str | None:
    """The zoo's own file that ``file_name`` is, else None. Compared ignoring case: a zoo may lie on a
    case-insensitive file system (macOS's, Windows'), where Manifest.json is manifest.json."""
    return next((own for own in ZOO_FILES if own.casefold() == file_name.casefold()), None)


def check_model_name(name: str) -> str:
    """``name`` if it is a safe zoo name (``check_name``) whose files NAME.pt and NAME.json are none of the
    zoo's own files (``ZOO_FILES``), else PredictorError saying which file it would overwrite."""
    check_name(name)
    for file_name in (f"{name}.pt", f"{name}.json"):
        own = zoo_file(file_name)
        if own is not None:
            raise PredictorError(
                f"zoo name {name!r} is reserved: its file {file_name} would overwrite {own}, the zoo's "
                f"{ZOO_FILES[own]} (names are compared ignoring case); pick another name"
            )
    return name


def is_zoo_file(root: Path, path: Path) -> bool:
    """Whether the resolved ``path`` is one of the zoo ``root``'s own files (``ZOO_FILES``)."""
    return path.parent == root.resolve() and zoo_file(path.name) is not None


@contextmanager
def zoo_lock(directory: str | Path) -> Iterator[Path]:
    """Hold the zoo's exclusive lock (``LOCK_NAME`` in it, made with the directory if need be) for a
    read-modify-write of its manifest: two writers that both read the old manifest would each write it back
    with their own change only, and the other's entry would be lost. Yields the directory."""
    root = Path(directory)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise PredictorError(f"{root / LOCK_NAME}: cannot lock the zoo ({exc.strerror or exc})") from None
    with locked(root / LOCK_NAME, "lock the zoo"):
        yield root


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

    def seen_in_training(self, paths: list[Path]) -> list[tuple[Path, str, str]]:
        """``(path, split, name)`` for each of ``paths`` whose content is a file this model records it was
        trained (split "train") or validated ("val") on, by sha256, under the name it records there."""
        from predictors.hashing import sha256_file

        recorded = self.training_data.get("files")
        if not isinstance(recorded, dict):
            return []
        seen = {
            sha: (split, name)
            for split in ("val", "train")  # a file in both was trained on, which says more
            if isinstance(recorded.get(split), dict)
            for name, sha in recorded[split].items()
        }
        found = []
        for path in paths:
            sha = sha256_file(path)
            if sha in seen:
                found.append((path, *seen[sha]))
        return found

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
    _check_version(document, path)
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


def _check_version(document: dict, path: Path) -> None:
    """Refuse a manifest of a layout this code does not know (a newer crowdmpc's): its entries could mean
    something else, and adding to it would write it back in the old layout. No "version" is version 1."""
    version = document.get("version", 1)
    readable = range(1, MANIFEST_VERSION + 1)
    if type(version) is int and version in readable:  # type(): True is no version
        return
    newer = (
        "; a newer crowdmpc wrote it: upgrade crowdmpc to read it"
        if type(version) is int and version > 0
        else ""
    )
    raise PredictorError(
        f'{path}: zoo manifest "version" {short_repr(version)} is not one this crowdmpc reads (version '
        f"{', '.join(map(str, readable))}){newer}"
    )


def write_manifest(entries: dict[str, ZooEntry], directory: str | Path) -> Path:
    """Write the manifest of the zoo at ``directory`` (atomically and durably: ``write_text_durably``). A
    writer that read the manifest first holds ``zoo_lock`` from that read to this write."""
    path = Path(directory) / MANIFEST_NAME
    path.parent.mkdir(parents=True, exist_ok=True)
    document = {
        "format": MANIFEST_FORMAT,
        "version": MANIFEST_VERSION,
        "models": [entries[name].to_json() for name in sorted(entries)],
    }
    try:
        write_text_durably(path, json.dumps(document, indent=2) + "\n")
    except OSError as exc:
        if exc.filename is not None:  # a name is given already (the temporary's, at its open or rename)
            raise
        # a write's error names no file: the manifest's, for the CLI's line (a full disk: "could not write")
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    return path
