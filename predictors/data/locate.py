"""Where the data is: the data directory, the prepared splits (built and cached on first use), and the files
of each evaluation protocol.

A data directory is either

* a *prepared* directory written by ``crowdmpc data prepare`` (``manifest.json``,
  ``{train,val,test}/*.ndjson``),
* or a *raw* directory like the team's shared data: ``raw_ewap/seq_{eth,hotel}/obsmat.txt`` (or the
  ``raw_ewap`` directory itself), optionally with ``trajnetpp_vita/train/real_data/*.ndjson`` beside it.
  The raw annotations are prepared once into ``<cache>/prepared/<content hash>`` (cache:
  ``$CROWDMPC_CACHE``, else ``~/.cache/crowdmpc``); an entry whose files are no longer those its manifest
  lists is prepared again and replaced.

Protocols (data/README.md explains them):

* ``paper``: train = train splits of ETH and Hotel, val = their val splits, test = the test split of
  ``dataset`` (ETH by default).
* ``loo`` (leave one sequence out): test = the same test split; train = every TrajNet++ training file
  of another sequence (zara01, zara03, students001, students003) plus the train split of the other BIWI
  sequence (Hotel), val = that sequence's val split. Nothing from ETH is used for training or validation.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import shutil
import sys
from pathlib import Path
from typing import Final

from predictors.data.ewap import EWAP_SEQUENCES, SPLITS
from predictors.data.prepare import CONVERTER_VERSION, STAGING_INFIX, prepare_ewap
from predictors.data.selfcheck import default_references
from predictors.data.validate import require_file
from predictors.errors import DuplicateKey, PredictorError, unique_keys
from predictors.hashing import sha256_file
from predictors.home import expand_home, home_dir
from predictors.locking import locked, pid_alive

DATA_ENV: Final[str] = "CROWDMPC_DATA"
CACHE_ENV: Final[str] = "CROWDMPC_CACHE"
VITA_TRAIN: Final[Path] = Path("trajnetpp_vita") / "train" / "real_data"
PROTOCOLS: Final[tuple[str, ...]] = ("paper", "loo")
DATASETS: Final[tuple[str, ...]] = tuple(EWAP_SEQUENCES)
# The names a manifest may list: <split>/<NAME>.ndjson inside its folder, no absolute path, no "..", nothing
# hidden (a manifest naming /etc/passwd had it opened and hashed).
SPLIT_FILE: Final[re.Pattern[str]] = re.compile(rf"({'|'.join(SPLITS)})/[^/\\\0.][^/\\\0]*\.ndjson")


def resolve_data_dir(data_dir: str | Path | None) -> Path:
    """``data_dir`` if given, else ``$CROWDMPC_DATA``; it must exist."""
    named = "--data-dir"
    if data_dir is None or str(data_dir) == "":
        data_dir, named = os.environ.get(DATA_ENV) or None, f"${DATA_ENV}"
        if data_dir is None:
            raise PredictorError(
                f"no data directory: pass --data-dir DIR or set {DATA_ENV} (a prepared directory from "
                "`crowdmpc data prepare`, or a directory holding raw_ewap/; see data/README.md)"
            )
    path = expand_home(str(data_dir), named)
    if not path.is_dir():
        raise PredictorError(f"data directory {path} {_not_a_directory(path)}")
    return path


def _not_a_directory(path: Path) -> str:
    """Why ``path``, which is no directory, is none: a missing path, a file, or a symbolic-link loop."""
    try:
        path.stat()
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return "is a symbolic-link loop"
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            return "does not exist"
        return f"cannot be read ({exc.strerror or exc})"
    return "is not a directory"


def cache_root() -> Path:
    """``$CROWDMPC_CACHE``, else ``$XDG_CACHE_HOME/crowdmpc`` (an absolute ``XDG_CACHE_HOME`` only, as the
    XDG spec says), else ``~/.cache/crowdmpc`` (not created here: reading needs no directory). The compile
    cache's root is the same folder (``mpc.cache_location.cache_dir``: mpc imports nothing of predictors)."""
    root = os.environ.get(CACHE_ENV)
    if root:
        return expand_home(root, f"${CACHE_ENV}")
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg and Path(xdg).is_absolute():
        return Path(xdg) / "crowdmpc"
    return home_dir("the cache", f"set ${CACHE_ENV}") / ".cache" / "crowdmpc"


def writable_cache_dir(*parts: str) -> Path:
    """``cache_root() / parts``, created, about to be written in; a PredictorError naming $CROWDMPC_CACHE and
    what is wrong (a file in the way, no permission) when it cannot be, instead of an OSError deep inside
    the writer about one of its temporary files."""
    path = cache_root().joinpath(*parts)
    problem = _unwritable(path)
    if problem is None:
        return path
    root = os.environ.get(CACHE_ENV)
    named = f"${CACHE_ENV}={root}" if root else f"the cache {cache_root()} (default; ${CACHE_ENV} unset)"
    raise PredictorError(f"{named}: {problem}; set ${CACHE_ENV} to a writable directory")


def _unwritable(path: Path) -> str | None:
    """Why the directory ``path`` cannot be written in, creating it (and its parents) when it can.
    (mpc.cache_location checks its directory alike; mpc does not import predictors.)"""
    existing = next(p for p in (path, *path.parents) if os.path.lexists(p))
    if not existing.is_dir():  # a file, or a dangling or looping symbolic link
        return f"{existing} is not a directory"
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):  # a read-only or foreign place
            return f"{existing} is not writable ({exc.strerror})"
        return f"{path} cannot be created ({exc.strerror or exc})"
    if not os.access(path, os.W_OK | os.X_OK):
        return f"{path} is not writable"
    return None


def read_manifest(directory: Path) -> dict | None:
    """The manifest of a complete prepared directory, else None: each file it lists is there with the size
    and sha256 it records (``prepared_mismatch`` says which is not)."""
    manifest = load_manifest(directory)
    if manifest is None or prepared_mismatch(directory, manifest) is not None:
        return None
    return manifest


def load_manifest(directory: Path) -> dict | None:
    """The prepared manifest in ``directory``; None where there is none or it is unreadable (every reader then
    says to prepare the folder again); PredictorError naming it for a key given twice, which json read as the
    last without a word, as every JSON file a user may edit is refused (``unique_keys``)."""
    manifest_path = directory / "manifest.json"
    if not manifest_path.is_file():
        return None
    try:
        manifest = json.loads(manifest_path.read_text(encoding="utf-8"), object_pairs_hook=unique_keys)
    except DuplicateKey as exc:  # before ValueError, which it is
        raise PredictorError(f"{manifest_path}: {exc}") from None
    # ValueError: UnicodeDecodeError, JSONDecodeError and an integer past Python's 4300 digits, which json
    # raises as a plain ValueError; RecursionError: nesting past the stack (json's parser recurses)
    except (OSError, ValueError, RecursionError):
        return None
    if not isinstance(manifest, dict) or manifest.get("format") != "crowdmpc-prepared":
        return None
    if not isinstance(manifest.get("files", {}), dict):
        return None
    return manifest


def prepared_mismatch(directory: Path, manifest: dict) -> str | None:
    """How the first file the manifest of ``directory`` lists differs from it (missing, another size or
    sha256: files of another preparation beside this manifest), or None. Hashing the splits costs about
    a millisecond per MB, little beside reading them. A name that is no split file is said before any file
    is opened: a manifest names only files of its own folder."""
    files = manifest.get("files", {})
    foreign = next((name for name in files if SPLIT_FILE.fullmatch(name) is None), None)
    if foreign is not None:
        return f"manifest.json is malformed: it lists {foreign!r}, not a file <split>/<NAME>.ndjson in it"
    for name, entry in files.items():
        path = directory / name
        if not path.is_file():
            return f"lacks {name}"
        entry = entry if isinstance(entry, dict) else {}
        size = path.stat().st_size
        if isinstance(entry.get("bytes"), int) and size != entry["bytes"]:
            return f"{name} has {size} bytes, the manifest says {entry['bytes']}"
        if isinstance(entry.get("sha256"), str) and sha256_file(path) != entry["sha256"]:
            return f"{name} is not the file the manifest lists (sha256 differs)"
    return None


def raw_ewap_dir(directory: Path) -> Path | None:
    for candidate in (directory / "raw_ewap", directory):
        if all((candidate / seq / "obsmat.txt").is_file() for seq in EWAP_SEQUENCES.values()):
            return candidate
    return None


def raw_ewap_problem(directory: Path) -> str | None:
    """One line naming an ``obsmat.txt`` where ``raw_ewap_dir`` looks that is there but no regular file (a
    folder, a FIFO, a dangling link), if any: the general "expected a BIWI EWAP directory" left the user to
    find which of the four places was wrong."""
    for candidate in (directory / "raw_ewap", directory):
        for seq in EWAP_SEQUENCES.values():
            path = candidate / seq / "obsmat.txt"
            if os.path.lexists(path) and not path.is_file():
                try:
                    require_file(path, " (expected a BIWI EWAP obsmat.txt)")
                except PredictorError as exc:
                    return str(exc)
    return None


def prepared_dir(data_dir: str | Path | None, *, log=None, progress: bool | None = None) -> Path:
    """The prepared directory for ``data_dir`` (module doc); raw data is prepared into the cache once."""
    directory = resolve_data_dir(data_dir)
    if read_manifest(directory) is not None:
        return directory
    if (directory / "manifest.json").is_file():
        manifest = load_manifest(directory)
        what = prepared_mismatch(directory, manifest) if manifest is not None else None
        raise PredictorError(
            f"{directory / 'manifest.json'} exists but the prepared data is incomplete or unreadable"
            f"{' (' + what + ')' if what else ''}; re-run `crowdmpc data prepare`"
        )
    raw = raw_ewap_dir(directory)
    if raw is None and (problem := raw_ewap_problem(directory)) is not None:
        raise PredictorError(problem)  # which file, rather than "holds neither ..."
    if raw is None:
        raise PredictorError(
            f"{directory} holds neither prepared splits (manifest.json and train/val/test/*.ndjson from "
            "`crowdmpc data prepare`) nor raw BIWI EWAP annotations (raw_ewap/seq_eth/obsmat.txt and "
            "raw_ewap/seq_hotel/obsmat.txt); see data/README.md"
        )
    target = _cache_entry(raw)
    if read_manifest(target) is not None:
        return target
    writable_cache_dir("prepared")
    log = log or (lambda msg: print(msg, file=sys.stderr))
    # Held for the whole preparation: two `train` runs started at once on an empty cache each prepared the
    # same entry (40 s of CPU and more apiece); the second now waits and takes the first's.
    with locked(
        _entry_lock(target),
        "prepare the cached data",
        waiting=lambda: log(f"waiting for another process preparing {target}"),
    ):
        if read_manifest(target) is not None:
            return target
        # no time promised ("about half a minute" was not): the machine decides, 41 s of CPU idle, 96-100 s
        # and minutes of wall time on a loaded one (README.md, Data)
        log(
            f"preparing {raw} into {target} ({_why_prepare(target)}; this takes a while, longer on a busy "
            "machine: the TrajNet++ categorisation's Kalman fits, most of it)"
        )
        staging = target.with_name(f"{target.name}.{os.getpid()}.tmp")
        _remove_dead_leftovers(target)
        shutil.rmtree(staging, ignore_errors=True)
        prepare_ewap(
            raw, staging, references=default_references(raw), progress=progress, log=log, log_dir=target
        )
        _install_cache_entry(staging, target)
    return target


def _cache_entry(raw: Path) -> Path:
    """The cache entry the raw data in ``raw`` is prepared into, keyed by the converter and its content."""
    digest = hashlib.sha256(CONVERTER_VERSION.encode())
    for seq in EWAP_SEQUENCES.values():
        digest.update(sha256_file(raw / seq / "obsmat.txt").encode())
    return cache_root() / "prepared" / digest.hexdigest()[:16]


def prepared_location(data_dir: str | Path | None) -> Path | None:
    """Where ``prepared_dir(data_dir)`` reads the prepared files, found without preparing anything: the
    folder itself when it holds a manifest, else its raw data's cache entry; None where that cannot be told
    (no such folder, neither kind of data, an unreadable file), which ``prepared_dir`` then says."""
    try:
        directory = resolve_data_dir(data_dir)
        if (directory / "manifest.json").is_file():
            return directory
        raw = raw_ewap_dir(directory)
        return None if raw is None else _cache_entry(raw)
    except (PredictorError, OSError):
        return None


def _entry_lock(target: Path) -> Path:
    """The lock file beside the cache entry ``target``."""
    return target.with_name(f".{target.name}.lock")


def _why_prepare(target: Path) -> str:
    """Why the cache entry ``target``, not a good one, is prepared: first use, or what is wrong with it."""
    if not os.path.lexists(target):
        return "first use only"
    manifest = load_manifest(target)
    what = (prepared_mismatch(target, manifest) if manifest is not None else None) or "no readable manifest"
    return f"the cached one is damaged: {what}; it is replaced"


def _remove_dead_leftovers(target: Path) -> None:
    """What preparations of ``target`` killed on the way left beside it: their staging entry, prepare_ewap's
    staging folder beside that, a damaged entry moved aside. Each name holds its process's pid, the staging
    folder's twice, so prepare_ewap's own sweep of killed stagings (beside the folder this process names)
    never matches one of another process, and nothing else removes them."""
    name, infix = re.escape(target.name), re.escape(STAGING_INFIX)
    left = re.compile(rf"{name}\.(\d+)\.tmp|\.{name}\.(\d+)\.tmp{infix}\d+\.tmp|\.{name}\.(\d+)\.old")
    if not target.parent.is_dir():
        return
    for entry in target.parent.iterdir():
        match = left.fullmatch(entry.name)
        if match is not None and not pid_alive(int(next(pid for pid in match.groups() if pid))):
            _remove(entry)


def _install_cache_entry(staging: Path, target: Path) -> None:
    """The fresh preparation ``staging`` renamed to the cache entry ``target``, under the caller's lock
    (``_entry_lock``). A good entry already there (installed without that lock) is kept (it holds the same
    files); a damaged one (a file edited or lost: ``read_manifest``
    refuses it) is moved aside to a hidden name and replaced, where the rename onto it failed on every run. It
    is only a cache: nothing of the user's is in it."""
    aside = target.with_name(f".{target.name}.{os.getpid()}.old")
    try:
        if read_manifest(target) is not None:
            return
        if os.path.lexists(target):
            os.rename(target, aside)
        staging.rename(target)
    except OSError as exc:
        if read_manifest(target) is not None:  # a process that takes no lock (an older crowdmpc) installed it
            return
        raise PredictorError(
            f"the cached preparation {target} cannot be replaced ({exc.strerror or exc}); delete it and run "
            "again"
        ) from None
    finally:
        _remove(staging)
        _remove(aside)


def _remove(path: Path) -> None:
    """``path`` gone, whatever it is; a link is removed, never what it points to."""
    if path.is_symlink() or path.is_file():
        path.unlink(missing_ok=True)
    else:
        shutil.rmtree(path, ignore_errors=True)


def vita_train_dir(data_dir: Path, prepared: Path) -> Path | None:
    """The TrajNet++ training files: in the data directory, or beside the raw data it was prepared from --
    the raw data in it, when it is a raw directory (prepared into the cache). A cache entry's own
    ``source_dir`` is not asked: the entry is keyed by the raw files' content, so it names whichever copy of
    them was prepared first, and a copy without TrajNet++ files trained on another folder's."""
    candidates = [data_dir / VITA_TRAIN]
    if prepared == data_dir:
        source = (read_manifest(prepared) or {}).get("source_dir")
        beside = Path(source).parent if source else None
    else:
        raw = raw_ewap_dir(data_dir)
        beside = Path(os.path.abspath(raw)).parent if raw is not None else None
    if beside is not None:
        candidates.append(beside / VITA_TRAIN)
    for candidate in candidates:
        if candidate.is_dir() and any(candidate.glob("*.ndjson")):
            return candidate
    return None


def protocol_files(
    data_dir: str | Path | None,
    protocol: str,
    dataset: str = "biwi_eth",
    *,
    log=None,
    progress: bool | None = None,
) -> dict[str, list[Path]]:
    """``{"train": [...], "val": [...], "test": [...]}``: the ndjson files of ``protocol`` for ``dataset``."""
    if protocol not in PROTOCOLS:
        raise PredictorError(f"unknown protocol {protocol!r}; choose from {list(PROTOCOLS)}")
    if dataset not in DATASETS:
        raise PredictorError(f"unknown dataset {dataset!r}; choose from {list(DATASETS)}")
    directory = resolve_data_dir(data_dir)
    prepared = prepared_dir(directory, log=log, progress=progress)

    def split_file(split: str, name: str) -> Path:
        return prepared / split / f"{name}.ndjson"

    if protocol == "paper":
        files = {
            "train": [split_file("train", name) for name in DATASETS],
            "val": [split_file("val", name) for name in DATASETS],
            "test": [split_file("test", dataset)],
        }
    else:
        vita = vita_train_dir(directory, prepared)
        if vita is None:
            raise PredictorError(
                f"--protocol loo needs the TrajNet++ training files ({VITA_TRAIN}/*.ndjson) in {directory} "
                "or beside the raw data it was prepared from; see data/README.md"
            )
        others = [name for name in DATASETS if name != dataset]
        # the BIWI sequences come from our own splits, so the whole-sequence TrajNet++ hotel file is left out
        # (it would overlap the val split)
        external = sorted(p for p in vita.glob("*.ndjson") if p.stem not in DATASETS)
        files = {
            "train": external + [split_file("train", name) for name in others],
            "val": [split_file("val", name) for name in others],
            "test": [split_file("test", dataset)],
        }
    missing = [str(p) for split in SPLITS for p in files[split] if not p.is_file()]
    if missing:
        raise PredictorError(f"prepared data in {prepared} lacks {missing}; re-run `crowdmpc data prepare`")
    return files
