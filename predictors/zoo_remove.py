"""Taking a model out of the user zoo: ``remove_from_zoo`` removes an entry and its files,
``remove_leftovers`` the hidden temporaries a stopped add or remove left (``zoo_edit.leftover_files``).
Every change of the manifest holds the zoo's lock (``predictors.manifest.zoo_lock``), as an add's does
(``predictors.zoo_edit``).
"""

from __future__ import annotations

import os
from pathlib import Path

from predictors.checkpoint import check_name
from predictors.durable import sync_folder
from predictors.errors import PredictorError
from predictors.manifest import MANIFEST_NAME, ZooEntry, is_zoo_file, write_manifest, zoo_lock
from predictors.zoo import checkpoints_dir, read_manifest, writable_zoo_dir
from predictors.zoo_edit import leftover_files, staged_names


def remove_from_zoo(name: str, directory: str | Path | None = None) -> tuple[ZooEntry, Path]:
    """Remove entry ``name`` from the user zoo (``directory``, else ``user_zoo_dir()``): its files (those no
    other entry names, a symbolic link itself and never the file it points to, and never one of the zoo's
    own: an entry added under a name reserved since may name one) are first renamed to hidden temporaries
    (.NAME.pt.PID.removed), then the manifest entry goes, then the temporaries, and those an earlier add or
    remove of ``name`` left. A remove stopped on the way leaves either the entry (its files gone: `zoo remove
    NAME` again finishes it) or hidden temporaries of ours (``remove_leftovers``), never files that look like
    a model no entry names. Returns the entry and the zoo directory."""
    check_name(name)  # not check_model_name: such an entry must stay removable
    root = writable_zoo_dir(directory)
    _entry_to_remove(name, root, read_manifest(root), directory)  # before the lock creates the directory
    with zoo_lock(root):  # another add or remove may have written the manifest since: read it again
        entries = read_manifest(root)
        entry = _entry_to_remove(name, root, entries, directory)
        del entries[name]
        manifest = root / MANIFEST_NAME
        # inside the zoo: checked when the manifest was read
        files = _named_files(entry, root, manifest) | _being_added(entry, root)
        still_used = {
            path
            for other in entries.values()
            for path in (*other.paths(root, manifest), *_named_files(other, root, manifest))
        }
        doomed = [path for path in files - still_used if not is_zoo_file(root, path)]
        parked = [path.with_name(f".{path.name}.{os.getpid()}.removed") for path in doomed]
        for path, hidden in zip(doomed, parked, strict=True):
            if path.exists() or path.is_symlink():
                os.replace(path, hidden)
        # on disk before the manifest drops the entry: lost after a power loss, the renames would leave
        # the entry's files under their names, a model that no entry names
        _sync_folders(doomed)
        try:
            write_manifest(entries, root)
        except OSError:  # a full disk, a quota: the manifest as it was, so the entry's files go back
            _put_back(doomed, parked)
            raise
        for hidden in parked:
            hidden.unlink(missing_ok=True)
        for model, path in leftover_files(root):  # an earlier add or remove of it stopped on the way
            if model == name:
                path.unlink(missing_ok=True)
    return entry, root


def _named_files(entry: ZooEntry, root: Path, manifest: Path) -> set[Path]:
    """``entry``'s files as its manifest names them: a symbolic link in the zoo is itself the file, never
    the one it points to (the user's own, or another entry's), which removing it would take and leave the
    link dangling, refused by a later add of the name as a file no entry owns."""
    files = set()
    base = root.resolve()
    for relative, resolved in zip((entry.file, entry.config), entry.paths(root, manifest), strict=True):
        named = root / relative
        link = named.parent.resolve() / named.name
        inside = link.parent.is_relative_to(base)  # "../x/NAME.pt" may be a link back into the zoo
        files.add(link if inside and link.is_symlink() else resolved)
    return files


def _being_added(entry: ZooEntry, root: Path) -> set[Path]:
    """NAME.pt and NAME.json of an entry that names its add's staged files (``.NAME.pt.PID.new``: the add
    stopped between its manifest's writes), which that add was putting in place: its own, gone with it, or
    left as files no entry names, which a new add of NAME refuses."""
    names = staged_names(entry)
    return set() if names is None else {root / name for name in names}


def _put_back(doomed: list[Path], parked: list[Path]) -> None:
    """The files of an entry a remove had parked, back under their names: the manifest that would have
    dropped the entry could not be written, and an entry whose files are gone loads nowhere."""
    for path, hidden in zip(doomed, parked, strict=True):
        if os.path.lexists(hidden):
            os.replace(hidden, path)
    # the entry is still in the manifest: lost after a power loss, the renames would leave it without files
    _sync_folders(doomed)


def _sync_folders(paths: list[Path]) -> None:
    """The renames into the folders of ``paths`` on disk, each folder synced once."""
    for folder in sorted({path.parent for path in paths}):
        sync_folder(folder)


def remove_leftovers(name: str, directory: str | Path | None = None) -> tuple[list[Path], Path]:
    """Remove the hidden temporaries of model ``name`` that no entry of the user zoo (``directory``, else
    ``user_zoo_dir()``) names (``leftover_files``). Never NAME.pt or NAME.json: a folder given as the zoo may
    hold a training run's output, which no entry names either. Returns the files removed (none: nothing to
    do) and the zoo directory."""
    check_name(name)
    root = writable_zoo_dir(directory)
    if not root.is_dir():
        return [], root  # the lock would create it
    with zoo_lock(root):  # an add in progress holds it: its temporary files are not leftovers
        removed = [path for model, path in leftover_files(root) if model == name]
        for path in removed:
            path.unlink()
    return removed, root


def _entry_to_remove(
    name: str, root: Path, entries: dict[str, ZooEntry], directory: str | Path | None
) -> ZooEntry:
    """Entry ``name`` of the user zoo ``root``, or PredictorError saying where it is not."""
    if name in entries:
        return entries[name]
    if directory is None and name in read_manifest(checkpoints_dir()):
        raise PredictorError(
            f"{name!r} is a model of the shipped zoo {checkpoints_dir()}, which is read-only"
        )
    raise PredictorError(f"the user zoo {root} has no entry {name!r}; it has {sorted(entries)}")


def remove_calibrations(name: str, directory: str | Path | None = None) -> tuple[int, Path]:
    """Remove every calibration block of predictor ``name`` from the user zoo's calibrations.json
    (``directory``, else ``user_zoo_dir()``); how many went and the file. ``remove_from_zoo`` keeps them: a
    zoo add of the same weights plans with them again, and a sweep planned with them then resumes (a
    recalibration's margins would be refused as changed); this is how a user drops them."""
    from predictors.calibration_store import calibrations_path, read_calibration_file, write_blocks

    check_name(name)
    path = calibrations_path(writable_zoo_dir(directory))
    if not path.is_file():  # nothing to take: the lock would make the zoo's folder
        return 0, path
    with zoo_lock(path.parent):  # a calibrate storing its blocks meanwhile keeps them
        blocks = read_calibration_file(path)
        kept = [block for block in blocks if block.predictor != name]
        if len(kept) < len(blocks):
            write_blocks(path, kept)
    return len(blocks) - len(kept), path


def calibrations_of(name: str, directory: str | Path | None = None) -> tuple[int, Path]:
    """How many blocks of predictor ``name`` the user zoo's calibrations.json holds, and the file."""
    from predictors.calibration_store import calibrations_path, read_calibration_file

    path = calibrations_path(writable_zoo_dir(directory))
    return sum(block.predictor == name for block in read_calibration_file(path)), path
