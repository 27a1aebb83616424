"""The model zoo: trained predictors as ``state_dict`` + JSON config pairs, listed in ``manifest.json``.

A checkpoint is two files: ``NAME.pt`` (a plain ``state_dict`` of tensors, read with
``torch.load(..., weights_only=True)``, never a pickled object) and ``NAME.json`` (what to build: the model
kind of ``predictors.models``, its net's hyper-parameters, observed steps; ``"class"``, the predictor class,
is informational). A manifest records for each entry its files and their sha256, the training data
(protocol, files and their hashes) and validation/test metrics. Loading a zoo entry checks both hashes
first; a file that differs is refused with ``CheckpointMismatch``.

Two zoos, read in this order:

* the shipped zoo, ``checkpoints/`` (or ``$CROWDMPC_CHECKPOINTS``): read-only package data, its manifest
  tracked with the code, installed as the package ``crowdmpc_checkpoints``;
* the user zoo, ``$CROWDMPC_ZOO`` (default ``$XDG_DATA_HOME/crowdmpc/zoo``, else
  ``~/.local/share/crowdmpc/zoo``): where ``crowdmpc zoo add`` writes, with its own manifest. A user entry may
  not take a shipped entry's name.

A config names its model kind; a kind no source registers (``predictors.models``) is refused with a message
saying how to register it. A zoo file never makes crowdmpc import code.
"""

from __future__ import annotations

import importlib.resources
import os
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from predictors.checkpoint import CheckedPair, read_checkpoint
from predictors.errors import CheckpointMismatch, PredictorError, short_repr
from predictors.home import expand_home, home_dir
from predictors.manifest import (
    MANIFEST_NAME,
    ZooEntry,
    read_manifest_at,
)

if TYPE_CHECKING:
    from collections.abc import Mapping

    from predictors.learned import LearnedPredictor

CHECKPOINTS_ENV: Final[str] = "CROWDMPC_CHECKPOINTS"
CHECKPOINTS_DIRNAME: Final[str] = "checkpoints"  # the shipped zoo in the repository
CHECKPOINTS_PACKAGE: Final[str] = "crowdmpc_checkpoints"  # the same, installed (pyproject.toml's package-dir)
ZOO_ENV: Final[str] = "CROWDMPC_ZOO"
SHIPPED: Final[str] = "shipped"
USER: Final[str] = "user"


def checkpoints_dir(directory: str | Path | None = None) -> Path:
    """The shipped zoo: ``directory``, else ``$CROWDMPC_CHECKPOINTS`` (``~`` expanded), else
    ``shipped_checkpoints_dir()``."""
    if directory is not None:
        return Path(directory)
    env = os.environ.get(CHECKPOINTS_ENV)
    return expand_home(env, f"${CHECKPOINTS_ENV}") if env else shipped_checkpoints_dir()


def shipped_checkpoints_dir() -> Path:
    """The zoo shipped with this code: the repository's checkpoints/ beside the packages in a clone, else the
    installed package data ``crowdmpc_checkpoints`` (pyproject.toml maps checkpoints/ to that package).

    The clone's directory comes first so that a clone always reads its own zoo, even when a crowdmpc wheel is
    installed too or its editable install predates the mapping. PredictorError when neither exists."""
    clone = Path(__file__).resolve().parents[1]
    if (clone / "pyproject.toml").is_file() and (clone / CHECKPOINTS_DIRNAME / MANIFEST_NAME).is_file():
        return clone / CHECKPOINTS_DIRNAME
    try:
        installed = importlib.resources.files(CHECKPOINTS_PACKAGE)
    except ModuleNotFoundError:
        raise PredictorError(
            f"the shipped model zoo is missing: neither {clone / CHECKPOINTS_DIRNAME} nor the package "
            f"{CHECKPOINTS_PACKAGE!r}; reinstall crowdmpc, or set {CHECKPOINTS_ENV} to a zoo directory"
        ) from None
    if not isinstance(installed, Path):  # e.g. installed inside a zip: torch.load needs a real file
        raise PredictorError(
            f"the shipped model zoo {installed} is not a directory on disk; install crowdmpc unpacked "
            f"(pip install), or set {CHECKPOINTS_ENV} to a zoo directory"
        )
    return installed


def user_zoo_dir(directory: str | Path | None = None) -> Path:
    """The user zoo: ``directory``, else ``$CROWDMPC_ZOO`` (``~`` expanded), else
    ``$XDG_DATA_HOME/crowdmpc/zoo`` (an absolute ``XDG_DATA_HOME`` only, as the XDG spec says), else
    ``~/.local/share/crowdmpc/zoo``."""
    if directory is not None:
        return Path(directory)
    env = os.environ.get(ZOO_ENV)
    if env:
        return expand_home(env, f"${ZOO_ENV}")
    data = os.environ.get("XDG_DATA_HOME")
    if data and Path(data).is_absolute():
        return Path(data) / "crowdmpc" / "zoo"
    return home_dir("the user zoo", f"set ${ZOO_ENV}") / ".local" / "share" / "crowdmpc" / "zoo"


def _resolved(path: Path) -> Path:
    try:
        return path.resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop
        raise PredictorError(f"zoo directory {path} cannot be resolved: {exc}") from None


def is_shipped(directory: str | Path) -> bool:
    """Whether ``directory`` is the shipped zoo or lies inside it (symbolic links followed)."""
    return _resolved(Path(directory)).is_relative_to(_resolved(checkpoints_dir()))


def writable_zoo_dir(directory: str | Path | None = None) -> Path:
    """The user zoo ``zoo add`` and ``zoo remove`` write into; PredictorError when it is the shipped zoo."""
    root = user_zoo_dir(directory)
    if is_shipped(root):
        where = f"${ZOO_ENV}" if directory is None else "the zoo directory"
        raise PredictorError(
            f"{where} {root} is the shipped zoo {checkpoints_dir()} (or inside it), which is read-only; "
            f"point {ZOO_ENV} at a directory of your own"
        )
    if root.exists() and not root.is_dir():
        raise PredictorError(f"the user zoo {root} is not a directory")
    return root


def readable_zoo_dir(directory: str | Path | None = None) -> Path:
    """The user zoo ``zoo list``, ``show``, ``verify`` and ``calibrations`` read; PredictorError when it is a
    file (passed over, the shipped zoo was listed alone) or when ``directory`` names one that does not exist
    (more likely a typo than the empty zoo a missing ``$CROWDMPC_ZOO`` is before the first ``zoo add``)."""
    root = user_zoo_dir(directory)
    if root.exists() and not root.is_dir():
        where = "--dir: " if directory is not None else f"${ZOO_ENV}: " if os.environ.get(ZOO_ENV) else ""
        raise PredictorError(f"{where}the user zoo {root} is a file, not a directory")
    if directory is not None and not root.exists():
        raise PredictorError(f"--dir {root}: no such user zoo (`crowdmpc zoo --dir DIR add` makes one)")
    return root


def read_manifest(directory: str | Path | None = None) -> dict[str, ZooEntry]:
    """Entries by name of the zoo at ``directory`` (``manifest.read_manifest_at``); ``None``: the shipped
    zoo's and then the user zoo's (a user entry under a shipped name is left out: the shipped one is what
    loads)."""
    if directory is None:
        merged: dict[str, ZooEntry] = {}
        for located in zoo_entries():
            merged.setdefault(located.entry.name, located.entry)
        return merged
    return read_manifest_at(directory)


# ---------------------------------------------------------------------------------- the shipped + user zoos
@dataclass(frozen=True)
class Located:
    """A zoo entry and where it lives."""

    source: str  # SHIPPED | USER
    root: Path  # its zoo directory
    entry: ZooEntry

    @property
    def manifest(self) -> Path:
        return self.root / MANIFEST_NAME


def zoo_roots(user_dir: str | Path | None = None) -> list[tuple[str, Path]]:
    """``(source, directory)`` of the shipped zoo and the user zoo (``user_dir``, else ``user_zoo_dir()``), in
    the order they are read; the user zoo is left out when it is the shipped one."""
    shipped = checkpoints_dir()
    roots = [(SHIPPED, shipped)]
    user = user_zoo_dir(user_dir)
    if user_dir is None and user.is_file():  # a mistyped $CROWDMPC_ZOO: its calibrations silently not read
        where = f"${ZOO_ENV}: " if os.environ.get(ZOO_ENV) else ""
        raise PredictorError(f"{where}the user zoo {user} is a file, not a directory")
    if _resolved(user) != _resolved(shipped):
        roots.append((USER, user))
    return roots


def zoo_entries(user_dir: str | Path | None = None) -> list[Located]:
    """Every entry of the shipped zoo, then every entry of the user zoo (including one that takes a shipped
    name, which never loads: ``verify`` reports it)."""
    return [
        Located(source, root, entry)
        for source, root in zoo_roots(user_dir)
        for entry in read_manifest(root).values()
    ]


def locate(name: str, user_dir: str | Path | None = None) -> Located | None:
    """The entry ``name`` loads: the shipped zoo's, else the user zoo's (read only when needed, so that a
    broken user manifest does not stop the shipped models); None when neither has it."""
    for source, root in zoo_roots(user_dir):
        entry = read_manifest(root).get(name)
        if entry is not None:
            return Located(source, root, entry)
    return None


def zoo_names(directory: str | Path | None = None) -> list[str]:
    """The names of the zoo at ``directory``; ``None``: of both zoos."""
    return sorted(read_manifest(directory))


def find_entry(name: str, directory: str | Path | None = None) -> ZooEntry:
    """The entry ``name`` of the zoo at ``directory`` (``None``: of both zoos), or UnknownPredictor."""
    if directory is None:
        located = locate(name)
        if located is not None:
            return located.entry
    else:
        entries = read_manifest(directory)
        if name in entries:
            return entries[name]
    from predictors.errors import UnknownPredictor

    raise UnknownPredictor(name, zoo_names(directory))


def load_located(located: Located, name: str | None = None) -> LearnedPredictor:
    """A located entry as a predictor, after checking both files' sha256 against its manifest."""
    return read_located(located, name).predictor


def read_located(located: Located, name: str | None = None) -> CheckedPair:
    """``load_located``'s predictor with the bytes of the files it was made from."""
    weights, config = located.entry.paths(located.root, located.manifest)
    return read_checkpoint(
        weights,
        config,
        name=name or located.entry.name,
        expected_sha256=located.entry.sha256,
        expected_config_sha256=located.entry.config_sha256,
        check_config=lambda document: check_kind(located, document),
    )


def check_kind(located: Located, document: Mapping[str, Any]) -> None:
    """Refuse the entry ``located`` whose config ``document`` (its bytes the entry's) names a model kind that
    nothing registers (a plugin's, without ``--plugin``), naming the entry, its manifest, the kind and how to
    register it. Every command that loads a zoo entry refuses it here in one line: simulate, evaluate,
    export and calibrate named the config file alone, the sweep the entry and its zoo. The config's kind, as
    loading builds it; its manifest's is informational (``zoo verify`` compares them)."""
    from predictors.models import UnknownModel, model_kind

    model = document.get("model")
    if not isinstance(model, str):
        return  # a legacy or malformed config: read_checkpoint's own words
    try:
        model_kind(model)
    except UnknownModel as exc:
        where = f"predictor {located.entry.name!r} of the {located.source} zoo ({located.manifest})"
        raise PredictorError(f"{where}: {exc}") from None


def load_zoo(name: str, directory: str | Path | None = None) -> LearnedPredictor:
    """Zoo entry ``name`` (of the zoo at ``directory``; ``None``: the shipped zoo, then the user zoo) as a
    predictor, after checking both files' sha256 against the manifest."""
    if directory is None:
        located = locate(name)
        if located is None:
            from predictors.errors import UnknownPredictor

            raise UnknownPredictor(name, zoo_names())
    else:
        root = Path(directory)
        located = Located(USER, root, find_entry(name, root))
    return load_located(located)


def shadowed(located: Located) -> bool:
    """Whether ``located`` is a user entry under a name the shipped zoo has (it never loads)."""
    return located.source == USER and located.entry.name in read_manifest(checkpoints_dir())


def never_loads_line(located: Located, taker: str) -> str:
    """The line saying that user entry ``located`` never loads, since ``taker`` has its name."""
    name = located.entry.name
    return (
        f"{located.manifest}: {taker} has this name, so this entry never loads; remove it "
        f"(`crowdmpc zoo remove {name}`) and add it under another name"
    )


def verify_entries(user_dir: str | Path | None = None) -> list[tuple[Located, str | None]]:
    """``(entry, problem or None)`` for every entry of both zoos: files present, hashes as recorded, weights
    loadable, no user entry under a shipped name."""
    results: list[tuple[Located, str | None]] = []
    for located in zoo_entries(user_dir):
        if shadowed(located):
            results.append((located, never_loads_line(located, "a shipped model")))
            continue
        try:
            results.append((located, disagreement(located, read_located(located).config)))
        except CheckpointMismatch as exc:
            results.append((located, _mismatch_line(exc, located, user_dir)))
        except PredictorError as exc:
            results.append((located, str(exc)))
    return results


def _mismatch_line(exc: CheckpointMismatch, located: Located, user_dir: str | Path | None) -> str:
    """``zoo verify``'s line of an entry whose file differs: what to do, not the loading refusal's advice to
    run ``zoo verify``, the command that prints it."""
    name = shlex.quote(located.entry.name)
    if located.source == SHIPPED:  # read-only, but to maintainers (`zoo add --shipped`)
        return (
            f"{exc.fault}: restore it, or add the model again (maintainers: `crowdmpc zoo add --shipped "
            f"FILE.pt --name {name} --replace`)"
        )
    option = "" if user_dir is None else f" --dir {shlex.quote(str(user_dir))}"
    return (
        f"{exc.fault}: restore it, add the model again (`crowdmpc zoo{option} add FILE.pt --name {name} "
        f"--replace`) or remove it (`crowdmpc zoo{option} remove {name}`)"
    )


def disagreement(located: Located, config_bytes: bytes) -> str | None:
    """Where ``located``'s manifest entry says other than its config (whose sha256 the entry holds, so the
    config is the pair's truth): its model kind or a value of its training record (epochs,
    limit_batches, seed ...). ``zoo list`` shows the entry's, loading takes the config's; a manifest edited
    by hand would show one model and run another. None when they agree. ``config_bytes``: the config as
    the entry loaded (``read_located``); read again, a config replaced since was reported on, not the one
    that loaded."""
    from predictors.checkpoint import CONFIG_FORMAT, parse_document

    entry = located.entry
    _, config = entry.paths(located.root, located.manifest)
    document = parse_document(config, config_bytes, CONFIG_FORMAT, "crowdmpc predictor config")
    trained = document.get("training")
    # not the class: an entry records the predictor class that loads it, a config the one that saved it
    pairs = [("model", entry.model, document.get("model"))]
    pairs += [  # of what both record: an entry added from a metrics file without them says nothing of them
        (f"training.{key}", entry.training[key], value)
        for key, value in (trained.items() if isinstance(trained, dict) else ())
        if key in entry.training
    ]
    for key, said, value in pairs:
        if value is not None and said != value:
            return (
                f"{located.manifest}: entry {entry.name!r} says {key} {short_repr(said)}, its config "
                f"{config.name} {short_repr(value)} (the manifest edited by hand?); add the model again with "
                "`crowdmpc zoo add --replace`, or restore the manifest"
            )
    return None


def verify(directory: str | Path | None = None) -> list[tuple[str, str | None]]:
    """``(name, problem or None)`` for every entry of the zoo at ``directory`` (``None``: of both zoos)."""
    if directory is None:
        return [(located.entry.name, problem) for located, problem in verify_entries()]
    root = Path(directory)
    results: list[tuple[str, str | None]] = []
    for name in zoo_names(root):
        try:
            located = Located(USER, root, find_entry(name, root))  # the entry read once: the one loaded
            results.append((name, disagreement(located, read_located(located).config)))
        except CheckpointMismatch as exc:
            results.append((name, _mismatch_line(exc, located, root)))
        except PredictorError as exc:
            results.append((name, str(exc)))
    return results
