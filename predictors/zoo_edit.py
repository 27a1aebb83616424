"""Writing a model zoo: ``add_to_zoo`` / ``add_entry`` copy a checkpoint pair into the user zoo (or, for the
maintainers, the shipped one) and record it in its manifest; ``predictors.zoo_remove`` takes a user entry out.
Every change of a manifest holds the zoo's lock (``predictors.manifest.zoo_lock``) from its read to its write.
Reading the zoos (``predictors.zoo``) needs none of this.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
from collections.abc import Callable, Collection
from dataclasses import replace as replace_fields
from functools import partial
from pathlib import Path
from typing import Any

from predictors.checkpoint import CONFIG_FORMAT, CONFIG_KEYS, CheckedPair, parse_document, read_checkpoint
from predictors.durable import replace_durably
from predictors.errors import PredictorError, short_key
from predictors.hashing import sha256_file
from predictors.manifest import (
    MANIFEST_NAME,
    ZooEntry,
    check_model_name,
    is_zoo_file,
    write_manifest,
    zoo_lock,
)
from predictors.zoo import SHIPPED, USER, checkpoints_dir, read_manifest, writable_zoo_dir

# the hidden names an add (_write_pair, _replace_with_link) or a remove gives a model's files on the way
TEMPORARY = re.compile(r"\.(?P<name>.+)\.(?:pt|json)\.\d+\.(?:new|link|removed)")


def add_to_zoo(weights: str | Path, **options: Any) -> ZooEntry:
    """Copy a checkpoint pair into the user zoo (``directory``, else ``user_zoo_dir()``) as
    ``NAME.pt``/``NAME.json`` and record it in its manifest: ``add_entry``'s options, without what it
    replaced."""
    return add_entry(weights, **options)[0]


def add_entry(
    weights: str | Path,
    *,
    name: str,
    protocol: str,
    training_data: dict,
    metrics: dict,
    training: dict | None = None,
    directory: str | Path | None = None,
    shipped: bool = False,
    replace: bool = False,
    check_pair: Callable[[CheckedPair], dict] | None = None,
) -> tuple[ZooEntry, ZooEntry | None]:
    """``add_to_zoo``: the entry now in the zoo, and the one it had under ``name`` before (None if none).

    The shipped zoo is read-only: a ``directory`` that is (or lies in) it is refused, and so is a ``name`` it
    has. A ``name`` the zoo has already is refused unless ``replace`` (and so is a name whose files would be
    the zoo's own, ``ZOO_FILES``), except for the very same entry: that is left as it is, ``replace`` or
    not (the one object returned as both), unless its files in the zoo were damaged since, which are then
    written again (an equal, new entry returned).
    ``shipped=True`` is the maintainers' way to add a model of a shipped kind to the shipped zoo itself
    (``directory`` then defaults to ``checkpoints_dir()``). Parallel adds and removes take turns
    (``zoo_lock``): every one's entry is in the manifest they leave.
    ``check_pair``: called with the pair as it loaded before its entry is made, for a caller's own refusal
    of the bytes that are kept (`zoo add`'s metrics); what it returns joins ``training`` (figures of those
    bytes)."""
    check_model_name(name)  # before anything is written: NAME becomes the files' names
    _check_not_built_in(name)
    weights = Path(weights)
    config = weights.with_suffix(".json")
    if shipped:
        root = checkpoints_dir(directory)
    else:
        root = writable_zoo_dir(directory)
        _check_not_shipped(name)
    entries = read_manifest(root)  # refuse to add to a manifest that does not read
    which = SHIPPED if shipped else USER
    _check_case_clash(name, entries, root, which)
    entry, weights_bytes, config_bytes = _new_entry(
        weights,
        check_config=partial(_check_shipped_kind, config) if shipped else None,
        check_pair=check_pair,
        name=name,
        protocol=protocol,
        training_data=training_data,
        metrics=metrics,
        training=training or {},
    )
    # checked before the lock, which creates the zoo directory: a refused add writes nothing
    if _unchanged(entries.get(name), entry, root, which, replace):
        return entry, entry
    _check_no_stray_file(entry, entries.get(name), root, which, (weights, config))
    with zoo_lock(root):  # another add or remove may have written the manifest since: read it again
        entries = read_manifest(root)
        _check_case_clash(name, entries, root, which)
        previous = entries.get(name)
        if _unchanged(previous, entry, root, which, replace):
            return entry, entry
        _check_no_stray_file(entry, previous, root, which, (weights, config))
        _write_pair(weights_bytes, config_bytes, entry, root, entries)
        _drop_leftovers(name, root)
    return entries[name], None if _stopped_add(previous, entry) else previous  # finished: no entry replaced


def _new_entry(
    weights: Path,
    *,
    check_config: Callable[[dict], None] | None,
    check_pair: Callable[[CheckedPair], dict] | None,
    name: str,
    **recorded: Any,
) -> tuple[ZooEntry, bytes, bytes]:
    """The entry of ``weights`` (and its config) under ``name``, the weights' bytes and the config's as the
    zoo keeps them (named ``name``); ``recorded``: ZooEntry's protocol, training_data, metrics and training;
    ``check_config``: ``read_checkpoint``'s, ``check_pair``: ``add_entry``'s. PredictorError when the pair
    does not load or the entry does not check."""
    config = weights.with_suffix(".json")
    # The bytes kept are the bytes that loaded, each file read once: read again to be hashed and copied, a
    # pair replaced meanwhile (a training run writing it) was added without a check.
    checked = read_checkpoint(weights, config, check_config=check_config)  # refuse a pair that does not load
    if check_pair is not None:
        recorded["training"] = {**recorded["training"], **check_pair(checked)}
    document = parse_document(config, checked.config, CONFIG_FORMAT, "crowdmpc predictor config")
    if "model" not in document:
        raise PredictorError(f'{config}: "model" is missing; `crowdmpc train` writes it')
    # refused on entering the zoo only: a config loaded from elsewhere may predate CONFIG_KEYS
    unknown = sorted(set(document) - CONFIG_KEYS)
    if unknown:
        raise PredictorError(
            f"{config}: unknown key {short_key(unknown[0])}; a predictor config holds {sorted(CONFIG_KEYS)}"
        )
    document["name"] = name
    config_bytes = (json.dumps(document, indent=2) + "\n").encode()
    entry = ZooEntry(  # checked (name, protocol, metrics ...) before anything is written
        name=name,
        cls=type(checked.predictor).__name__,
        model=document["model"],
        file=f"{name}.pt",
        sha256=hashlib.sha256(checked.weights).hexdigest(),
        config=f"{name}.json",
        config_sha256=hashlib.sha256(config_bytes).hexdigest(),
        **recorded,
    )
    return entry, checked.weights, config_bytes


def _unchanged(previous: ZooEntry | None, entry: ZooEntry, root: Path, which: str, replace: bool) -> bool:
    """Whether the zoo's entry ``previous`` under ``entry``'s name is ``entry`` itself (nothing to write, with
    ``replace`` or without); PredictorError when it is another one and ``replace`` was not asked for."""
    if previous is None:
        return False
    if _stopped_add(previous, entry):
        return False  # written again, to finish it
    if previous == entry:
        # adding the same thing twice changes nothing, --replace or not (replacing it with itself said
        # "replaced" and rewrote the files), unless the zoo's copy was damaged since: rewrite it
        return all(
            (root / name).is_file() and sha256_file(root / name) == digest
            for name, digest in ((entry.file, entry.sha256), (entry.config, entry.config_sha256))
        )
    if replace:
        return False
    # the entry may be the only copy of a model the user trained (or the paper's predictor, in the shipped
    # zoo): never lose it without being asked
    raise PredictorError(_taken(entry.name, root, which, previous, entry))


def _check_no_stray_file(
    entry: ZooEntry, previous: ZooEntry | None, root: Path, which: str, sources: tuple[Path, Path]
) -> None:
    """Refuse a NAME.pt or NAME.json linked to outside the zoo, or one there that is no file of its entry
    NAME (``previous``): the user's own (a training run's, in a folder given as the zoo), lost if replaced.
    One that is the file being added (``sources``: the weights and their config; ``zoo --dir RUN add
    RUN/NAME.pt``) is written with what it holds."""
    manifest = root / MANIFEST_NAME
    paths = entry.paths(root, manifest)
    owned = () if previous is None else previous.paths(root, manifest)
    if previous is not None and staged_names(previous) is not None:
        owned = paths  # an add of NAME stopped between its manifest's writes: NAME.pt, NAME.json are its own
    for file_name, path, source in zip((entry.file, entry.config), paths, sources, strict=True):
        if os.path.lexists(root / file_name) and path not in owned and not _same_file(path, source):
            whose = "is no file of its entry" if previous is not None else "the zoo has no entry"
            raise PredictorError(
                f"{root / file_name} is in the {which} zoo but {whose} {entry.name!r}; adding would replace "
                "it: move that file away, or add under another --name"
            )


def _same_file(path: Path, other: Path) -> bool:
    try:
        return os.path.samefile(path, other)
    except OSError:  # one of them is gone, or a dangling link
        return False


def _write_pair(
    weights_bytes: bytes, config_bytes: bytes, entry: ZooEntry, root: Path, entries: dict[str, ZooEntry]
) -> None:
    """Write the weights and the config, the bytes ``entry`` records the sha256 of, as its files in ``root``
    and record the entry in ``entries`` and the manifest.

    Never written over in place: an add interrupted at any instant (Ctrl-C, a kill, a full disk, a power
    loss) leaves a manifest whose entries all name files holding what it records. The new pair is written
    under temporary names (``.NAME.pt.PID.new``) and synced; the manifest then names those; then
    NAME.pt and NAME.json are replaced by links to them (each in one rename); the manifest then names
    NAME.pt and NAME.json; and the temporary names go. Until the first manifest switch, the old entry and its
    files are as they were; after it, the entry's files are never the ones being replaced."""
    staged = [root / f".{file_name}.{os.getpid()}.new" for file_name in (entry.file, entry.config)]
    try:
        _write_synced(staged[0], weights_bytes)
        _write_synced(staged[1], config_bytes)
        entries[entry.name] = replace_fields(entry, file=staged[0].name, config=staged[1].name)
        write_manifest(entries, root)
    except BaseException:
        for path in staged:
            path.unlink(missing_ok=True)
        raise
    # The manifest names the staged pair: NAME.pt and NAME.json are nobody's files until it names them again.
    # Not entry.paths(): a symbolic link NAME.pt in the zoo is replaced, never the file it points to.
    for path, file_name in zip(staged, (entry.file, entry.config), strict=True):
        _replace_with_link(path, root / file_name)
    entries[entry.name] = entry
    write_manifest(entries, root)
    for path in staged:
        path.unlink(missing_ok=True)


def staged_names(entry: ZooEntry) -> tuple[str, str] | None:
    """NAME.pt and NAME.json of an entry that names its add's staged copies (``.NAME.pt.PID.new``: the add
    stopped between its manifest's writes, ``_write_pair``); None for an entry naming its own files."""
    if not (TEMPORARY.fullmatch(entry.file) and TEMPORARY.fullmatch(entry.config)):
        return None
    return entry.file[1:].rsplit(".", 2)[0], entry.config[1:].rsplit(".", 2)[0]


def _stopped_add(previous: ZooEntry | None, entry: ZooEntry) -> bool:
    """Whether ``previous`` is ``entry``'s own add, stopped between its manifest's writes (``_write_pair``:
    the entry names its staged copies), which the same add finishes."""
    if previous is None or staged_names(previous) is None:
        return False
    return replace_fields(previous, file=entry.file, config=entry.config) == entry


def _drop_leftovers(name: str, root: Path) -> None:
    """The hidden copies an add or remove of ``name`` stopped on the way left (no entry names them, and the
    caller holds the lock: no add is writing them now), gone once an add of ``name`` has finished."""
    for model, path in leftover_files(root):
        if model == name:
            path.unlink(missing_ok=True)


def _replace_with_link(source: Path, target: Path) -> None:
    """Make ``target`` hold ``source``'s content in one rename: a hard link to it (a copy where the file
    system has none), made under a temporary name first."""
    link = target.with_name(f".{target.name}.{os.getpid()}.link")
    link.unlink(missing_ok=True)
    try:
        try:
            os.link(source, link)
        except OSError:  # no hard links here (FAT, some network file systems): a copy, which the rename syncs
            shutil.copyfile(source, link)
        replace_durably(link, target)
    finally:
        link.unlink(missing_ok=True)


def _write_synced(target: Path, data: bytes) -> None:
    """``data`` written to ``target`` and on disk before the call returns."""
    with target.open("wb") as copy:
        copy.write(data)
        copy.flush()
        os.fsync(copy.fileno())


def user_name_refusal(name: str) -> str | None:
    """Why ``add_to_zoo`` refuses ``name`` for a user model whatever the user zoo holds (a built-in
    predictor's name, a shipped model's), else None. ``crowdmpc train``'s zoo hint asks it, so the command it
    prints is one that ``zoo add`` takes."""
    return _built_in_refusal(name) or _shipped_refusal(name)


def _check_not_built_in(name: str) -> None:
    refusal = _built_in_refusal(name)
    if refusal is not None:
        raise PredictorError(refusal)


def _built_in_refusal(name: str) -> str | None:
    """Refuse the name of a predictor without weights (``registry.PREDICTORS``), in any case: that name
    loads the built-in, so the entry could never be reached."""
    from predictors.registry import PREDICTORS

    built_in = _same_ignoring_case(name, PREDICTORS)
    if built_in is None:
        return None
    return (
        f"zoo name {name!r} is the built-in predictor {built_in!r}, which that name always loads; "
        "pick another name"
    )


def _check_not_shipped(name: str) -> None:
    refusal = _shipped_refusal(name)
    if refusal is not None:
        raise PredictorError(refusal)


def _shipped_refusal(name: str) -> str | None:
    """Refuse a user model's ``name`` that the shipped zoo has, in any case: every clone has the shipped
    model, and two names a reader cannot tell apart would pick one or the other by a letter's case."""
    shipped_name = _same_ignoring_case(name, read_manifest(checkpoints_dir()))
    if shipped_name is None:
        return None
    spelled = "" if shipped_name == name else f" (as {shipped_name!r}: names are compared ignoring case)"
    return (
        f"zoo name {name!r} is taken by a model of the shipped zoo {checkpoints_dir()}{spelled}; "
        "pick another name (--name)"
    )


def _same_ignoring_case(name: str, names: Collection[str]) -> str | None:
    """The name in ``names`` that ``name`` is when case is ignored (itself if present), else None."""
    if name in names:
        return name
    return next((other for other in names if other.casefold() == name.casefold()), None)


def _check_case_clash(name: str, entries: dict[str, ZooEntry], root: Path, which: str) -> None:
    """Refuse ``name`` when the zoo has it in another case: on a case-insensitive file system (macOS's,
    Windows') Mine.pt is mine.pt, so adding it would overwrite that entry's weights under its sha256."""
    other = _same_ignoring_case(name, entries)
    if other is not None and other != name:
        raise PredictorError(
            f"the {which} zoo {root} already has {other!r}, which is {name!r} when case is ignored (their "
            f"files are the same on a case-insensitive file system); add it as --name {other} --replace to "
            "replace that entry, or under another --name"
        )


def _taken(name: str, root: Path, which: str, previous: ZooEntry, entry: ZooEntry) -> str:
    """The refusal of a name the zoo has: what the entry holds, and how to go on."""
    same = " (the same weights, with other metrics or settings)" if previous.sha256 == entry.sha256 else ""
    return (
        f"the {which} zoo {root} already has {name!r}: sha256 {previous.sha256[:12]}…, model "
        f"{previous.model}{same}; add it with --replace to replace that entry, or under another --name"
    )


def _check_shipped_kind(config: Path, document: dict) -> None:
    """Refuse a config whose model kind the project does not ship: every clone reads the shipped zoo, and
    it would then need a module (a plugin's, an entry point's) that the repository lacks. ``document``: the
    config as it loads (read_checkpoint's check_config): read apart before the load, a config replaced
    between the reads was checked and another one added."""
    from predictors.models import shipped as shipped_kinds

    model = document.get("model")
    kinds = sorted(shipped_kinds())
    if isinstance(model, str) and model not in kinds:
        raise PredictorError(
            f"{config}: model {model!r} is not a kind this project ships ({', '.join(kinds)}), so the "
            "shipped zoo cannot hold it; add it to your user zoo without --shipped"
        )


def leftover_files(root: Path) -> list[tuple[str, Path]]:
    """``(model name, path)`` of each hidden temporary in the zoo ``root`` that no entry of its manifest
    names: those of a ``remove_from_zoo`` (.NAME.pt.PID.removed) or an add (.NAME.pt.PID.new, .link)
    stopped on the way, or of one running now unless the caller holds ``zoo_lock``."""
    if not root.is_dir():
        return []
    manifest = root / MANIFEST_NAME
    owned = {path for entry in read_manifest(root).values() for path in entry.paths(root, manifest)}
    found = []
    for path in sorted(root.iterdir()):
        match = TEMPORARY.fullmatch(path.name)
        if match is None or not (path.is_file() or path.is_symlink()) or is_zoo_file(root, path.resolve()):
            continue
        if path.resolve() in owned or path in owned:
            continue
        found.append((match["name"], path))
    return found
