"""BIWI EWAP to the prepared data directory: each raw sequence read (``predictors.data.ewap``), split in time,
cut into TrajNet++ scenes per part (``predictors.data.trajnet_scenes``), written as
``{train,val,test}/<name>.ndjson`` with a ``manifest.json`` that records sources, parameters and hashes, so
that cached preparations can be checked and rebuilt when the conversion changes; optionally self-checked
against TrajNet++'s own files (``predictors.data.selfcheck``).
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import sys
import tempfile
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Final

import numpy as np

from predictors.data.ewap import (
    EWAP_SEQUENCES,
    SPLIT_FRACTIONS,
    SPLITS,
    infer_frame_step,
    read_obsmat,
    split_frames,
)
from predictors.data.ewap_checks import check_step_seconds, fast_steps_note
from predictors.data.selfcheck import Reference, compare_with_reference, describe_check
from predictors.data.trajnet_scenes import (
    CHUNK_SIZE,
    CHUNK_STRIDE,
    DEFAULT_SEED,
    MIN_LENGTH,
    TRAJNETPP_ACCEPTANCE,
    build_scenes,
    write_ndjson,
)
from predictors.durable import replace_durably, sync_folder
from predictors.errors import PredictorError
from predictors.hashing import sha256_file
from predictors.locking import pid_alive

# Bump when the conversion changes, so cached preparations are rebuilt.
CONVERTER_VERSION: Final[str] = "crowdmpc-ewap-1"
MANIFEST: Final[str] = "manifest.json"
# In a prepared folder while new files are moved in: its manifest is gone and `data prepare` may finish it.
INCOMPLETE_MARKER: Final[str] = ".prepare-incomplete"
STAGING_INFIX: Final[str] = ".prepare-"  # .NAME.prepare-PID.tmp beside the folder NAME being prepared


def prepare_ewap(
    raw_dir: str | Path,
    out_dir: str | Path,
    *,
    acceptance: tuple[float, float, float, float] | None = TRAJNETPP_ACCEPTANCE,
    categorize_scenes: bool = True,
    seed: int = DEFAULT_SEED,
    fractions: tuple[float, float] = SPLIT_FRACTIONS,
    references: dict[str, Reference] | None = None,
    progress: bool | None = False,
    log=print,
    log_dir: str | Path | None = None,
    note: Callable[[str], None] | None = None,
) -> dict:
    """Convert ``raw_dir/seq_eth`` and ``raw_dir/seq_hotel`` into ``out_dir/{train,val,test}/<name>.ndjson``
    and write ``out_dir/manifest.json``; with ``references`` ({name: a TrajNet++ conversion of the whole
    sequence}) also run the self-check (``compare_with_reference``). Without ``categorize_scenes`` scenes
    are untagged and none is dropped (much faster; see ``build_scenes``). The log names each file in
    ``log_dir`` (default ``out_dir``): a caller that moves ``out_dir`` into place names that place. ``note``
    takes the "note: ..." lines (default: stderr): steps no walker makes, splits without scenes. A sequence
    whose velocities imply another rate than 2.5 fps, or a conversion with no scene at all, raises
    ``PredictorError`` and leaves ``out_dir`` as it was. Returns the manifest."""
    raw_dir, out_dir = Path(raw_dir), Path(out_dir)
    log_dir = Path(log_dir) if log_dir is not None else out_dir
    sources = {name: raw_dir / seq / "obsmat.txt" for name, seq in EWAP_SEQUENCES.items()}
    missing = [str(p) for p in sources.values() if not p.is_file()]
    if missing:
        raise PredictorError(
            f"{raw_dir} is not a BIWI EWAP directory: missing {missing} (see data/README.md for the archive)"
        )
    # written into a staging folder beside ``out_dir`` and moved in only when complete (``_install``); beside
    # the folder a symbolic link names, on its file system when it can be (``_move`` copies across others)
    out_dir = out_dir.resolve()
    _check_out_dir(out_dir)
    staging = out_dir.parent / f".{out_dir.name}{STAGING_INFIX}{os.getpid()}.tmp"
    _remove_stale_staging(out_dir)
    shutil.rmtree(staging, ignore_errors=True)
    try:
        staging.mkdir(parents=True)
        manifest = _prepare_into(staging, raw_dir, sources, acceptance, categorize_scenes, seed, fractions,
                                 references, progress, log, log_dir, note or _to_stderr)  # fmt: skip
        _install(staging, out_dir, manifest)
    except OSError as exc:
        named = _naming_the_output(exc, (staging, out_dir), log_dir)
        if named is None:
            raise
        raise named from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return manifest


def _naming_the_output(exc: OSError, folders: tuple[Path, Path], log_dir: Path) -> OSError | None:
    """``exc`` raised again naming the output file under ``log_dir`` it was writing, None if it names no
    file of ``folders`` (the staging folder, the resolved output): an EIO at a sync (SyncFailed) named
    ``.out.prepare-PID.tmp/train/.biwi_eth.ndjson.PID.tmp``, a name the user never gave and that is removed
    before the line is read. A temporary's ``.NAME.PID.tmp`` and a copy's ``NAME.part`` (``_move``) are
    NAME's."""
    if exc.filename is None or exc.filename2 is not None or exc.errno is None:
        return None
    path = Path(os.fsdecode(exc.filename))
    for folder in folders:
        if path.is_relative_to(folder):
            name = path.name.removesuffix(".part")
            if name.startswith(".") and name.endswith(".tmp"):  # write_scenes' .NAME.PID.tmp
                stem, _, pid = name[1:-4].rpartition(".")
                name = stem if stem and pid.isdigit() else name
            named = log_dir / path.parent.relative_to(folder) / name
            return type(exc)(exc.errno, exc.strerror, str(named))
    return None


def _prepare_into(
    out_dir: Path,
    raw_dir: Path,
    sources: dict[str, Path],
    acceptance: tuple[float, float, float, float] | None,
    categorize_scenes: bool,
    seed: int,
    fractions: tuple[float, float],
    references: dict[str, Reference] | None,
    progress: bool | None,
    log,
    log_dir: Path,
    note: Callable[[str], None],
) -> dict:
    manifest = _new_manifest(raw_dir, acceptance, categorize_scenes, seed, fractions)
    options = dict(categorize_scenes=categorize_scenes, acceptance=acceptance, seed=seed, progress=progress)
    for name, source in sources.items():
        with_velocities = read_obsmat(source, velocities=True)
        tracks = np.ascontiguousarray(with_velocities[:, :4])
        frame_step = infer_frame_step(tracks[:, 0])
        # before any file is written: a 10 Hz file was labelled 2.5 fps and scored 4x too slow
        check_step_seconds(source, with_velocities, frame_step)
        fast = fast_steps_note(source, with_velocities, frame_step)
        if fast is not None:
            note(fast)
        parts = split_frames(tracks[:, 0], fractions)
        manifest["sources"][name] = {
            "path": str(source.resolve()),
            "sha256": sha256_file(source),
            "frame_step": frame_step,
        }
        manifest["files"].update(
            _write_parts(name, tracks, parts, frame_step, out_dir, options, log, log_dir)
        )
        reference = (references or {}).get(name)
        if reference is not None and Path(reference.path).is_file():
            check = _self_check(name, tracks, reference, frame_step, progress, log, out_dir)
            manifest["self_check"][name] = check
    _check_scenes_made(manifest, raw_dir, log_dir, note)
    (out_dir / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    return manifest


def _to_stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _check_scenes_made(manifest: dict, raw_dir: Path, log_dir: Path, note: Callable[[str], None]) -> None:
    """``PredictorError`` when no file holds a scene (too few frames: a prepare that wrote only empty files
    passed, and training then failed far from the cause); a note for each empty file, whose split a protocol
    may still read (an empty val part left the selection of the best epoch to the other sequence's few)."""
    empty = [name for name, entry in manifest["files"].items() if not entry["scenes"]]
    if len(empty) == len(manifest["files"]):
        raise PredictorError(
            f"--raw {raw_dir}: no scene in any split; a scene needs a pedestrian annotated at 21 "
            "consecutive steps within one part of the 70/10/20 % split of a sequence's frames"
        )
    for name in empty:
        note(
            f"note: {log_dir / name} holds no scenes (too few frames of its sequence in that split, or no "
            "pedestrian there whom TrajNet++'s scene rules keep)"
        )


def _install(staging: Path, out_dir: Path, manifest: dict) -> None:
    """Move the prepared files of ``staging`` into ``out_dir``, the manifest last. An old manifest goes
    first, with the marker of an unfinished install put down before it, so that a stop on the way leaves a
    folder with no manifest (never an old manifest beside new files) that ``data prepare`` may finish."""
    out_dir.mkdir(parents=True, exist_ok=True)
    for folder in sorted({(out_dir / name).parent for name in manifest["files"]}):
        folder.mkdir(exist_ok=True)
    _check_out_dir(out_dir)  # again: a link put down while the files were made
    marker = out_dir / INCOMPLETE_MARKER
    # O_NOFOLLOW: a link put down since the check is refused (ELOOP), never followed to create its target
    os.close(os.open(marker, os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW, 0o666))  # the umask decides
    (out_dir / MANIFEST).unlink(missing_ok=True)
    folders = sorted({(out_dir / name).parent for name in manifest["files"]} | {out_dir})
    for name in manifest["files"]:
        _move(staging / name, out_dir / name)
    for folder in folders:  # the files' names on disk before the manifest that says they are all there
        sync_folder(folder)
    _move(staging / MANIFEST, out_dir / MANIFEST)
    marker.unlink(missing_ok=True)  # another preparation into the folder may have finished first
    sync_folder(out_dir)


def _check_out_dir(out_dir: Path) -> None:
    """A split folder or the marker of ``out_dir`` that is a symbolic link (or a split that is no folder) is
    refused: the files moved into a linked val/ replaced those of the folder it named, outside ``out_dir``,
    and a linked marker was created where it pointed. The files and the manifest are renamed over, so a
    link in their place is replaced, never followed."""
    for name in (*SPLITS, INCOMPLETE_MARKER):
        entry = out_dir / name
        if entry.is_symlink():
            raise PredictorError(
                f"{entry} is a symbolic link; `data prepare` writes only inside {out_dir}: remove the link "
                "or prepare into another folder"
            )
        if name in SPLITS and entry.exists() and not entry.is_dir():
            raise PredictorError(f"{entry} is not a folder; remove it or prepare into another folder")


def _move(source: Path, target: Path) -> None:
    """``source`` to ``target`` in one rename; across file systems (``out_dir`` a mount point, such as a
    container's volume) copied beside ``target`` first, then renamed there."""
    try:
        replace_durably(source, target, sync_target_folder=False)
    except OSError as exc:
        if exc.errno != errno.EXDEV:
            raise
        part = target.with_name(f"{target.name}.part")
        part.unlink(missing_ok=True)  # copyfile would write through a link left there
        shutil.copyfile(source, part)
        replace_durably(part, target, sync_target_folder=False)


def _remove_stale_staging(out_dir: Path) -> None:
    """The staging folders beside ``out_dir`` of preparations killed on the way (their process is gone)."""
    if not out_dir.parent.is_dir():
        return
    prefix = f".{out_dir.name}{STAGING_INFIX}"
    for entry in out_dir.parent.iterdir():
        pid = entry.name[len(prefix) : -len(".tmp")]
        if not (entry.name.startswith(prefix) and entry.name.endswith(".tmp") and pid.isdigit()):
            continue
        if entry.is_symlink() or not entry.is_dir() or pid_alive(int(pid)):
            continue
        shutil.rmtree(entry, ignore_errors=True)


def _new_manifest(
    raw_dir: Path,
    acceptance: tuple[float, float, float, float] | None,
    categorize_scenes: bool,
    seed: int,
    fractions: tuple[float, float],
) -> dict:
    """The manifest before any sequence is converted: what was asked for, with empty per-sequence parts."""
    return {
        "format": "crowdmpc-prepared",
        "converter": CONVERTER_VERSION,
        "source_dir": str(raw_dir.resolve()),
        "parameters": {
            "chunk_size": CHUNK_SIZE,
            "chunk_stride": CHUNK_STRIDE,
            "min_length": MIN_LENGTH,
            "categorized": categorize_scenes,
            "acceptance": list(acceptance) if acceptance is not None and categorize_scenes else None,
            "seed": seed,
            "split_fractions": {
                "train": fractions[0],
                "val": fractions[1],
                "test": round(1 - sum(fractions), 9),
            },
        },
        "sources": {},
        "files": {},
        "self_check": {},
    }


def _write_parts(
    name: str,
    tracks: np.ndarray,
    parts: dict[str, np.ndarray],
    frame_step: int,
    out_dir: Path,
    scenes_options: dict,
    log,
    log_dir: Path,
) -> dict[str, dict]:
    """Each split part of one sequence as its own ndjson file; scene ids run on across the parts, so a
    sequence's ids stay unique. Logged as in ``log_dir``, where they will be (``out_dir`` is a staging
    folder, gone at the end). Returns the manifest's entries for the files written."""
    files: dict[str, dict] = {}
    next_id = 0
    for split in SPLITS:
        rows = tracks[np.isin(tracks[:, 0].astype(np.int64), parts[split])]
        scenes = build_scenes(rows, frame_step=frame_step, start_scene_id=next_id, **scenes_options)
        next_id += len(scenes)
        target = out_dir / split / f"{name}.ndjson"
        write_ndjson(target, scenes, rows)
        first, last = (int(parts[split][0]), int(parts[split][-1])) if len(parts[split]) else (None, None)
        files[f"{split}/{name}.ndjson"] = {
            "scenes": len(scenes),
            "frames": [first, last],
            "sha256": sha256_file(target),
            "bytes": target.stat().st_size,
        }
        shown = log_dir / split / target.name
        log(f"{name:<11} {split:<5} frames {first}-{last}: {len(scenes):5d} scenes -> {shown}")
    return files


def _self_check(
    name: str,
    tracks: np.ndarray,
    reference: Reference,
    frame_step: int,
    progress: bool | None,
    log,
    staging: Path,
) -> dict:
    """``compare_with_reference`` in a scratch directory, reported through ``log``; the manifest's entry.
    The scratch is inside ``staging``: a preparation killed meanwhile (``kill``, a timeout) left one in the
    temp directory that nothing removes, where the next preparation removes a killed one's staging."""
    with tempfile.TemporaryDirectory(prefix="selfcheck-", dir=staging) as workdir:
        check = compare_with_reference(
            tracks, reference, frame_step=frame_step, workdir=Path(workdir), progress=progress
        )
    for line in describe_check(name, check):
        log(line)
    return asdict(check)
