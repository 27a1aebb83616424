"""Stored conformal calibrations (``predictors.calibration.Calibration`` blocks): ``calibrations.json`` in a
zoo directory, beside the manifest, so that weightless predictors get a calibration too and recalibrating
never rewrites the manifest's hashes::

    {"format": "crowdmpc-calibrations", "version": 1, "calibrations": [block, ...]}

one block (``Calibration.to_json``) per (predictor, source, alpha, sensor range: ``Calibration.key``; a
closed-loop block made behind a sensor stands beside the one made with every human in view). The shipped
zoo's file (``predictors.zoo.checkpoints_dir``) holds the calibrations shipped with the models and is never
written: a user's calibrations go to the user zoo's file (``predictors.zoo.user_zoo_dir``), and a block
there replaces the shipped block of the same key. Functions given a ``directory`` read and write that
directory's file only.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from types import EllipsisType
from typing import Final

from predictors.calibration import SOURCES, Calibration, remaking_view
from predictors.checkpoint import node_kind, read_document
from predictors.conformal import alpha_text, check_alpha
from predictors.durable import write_text_durably
from predictors.errors import PredictorError, UnknownPredictor, short_repr
from predictors.manifest import CALIBRATIONS_NAME, zoo_lock  # the zoo's own files (ZOO_FILES), its lock
from predictors.zoo import (
    SHIPPED,
    USER,
    checkpoints_dir,
    is_shipped,
    read_manifest,
    user_zoo_dir,
    writable_zoo_dir,
)

CALIBRATIONS_FORMAT: Final[str] = "crowdmpc-calibrations"
CALIBRATIONS_VERSION: Final[int] = 1
# the model kind of a predictor's zoo entry as a caller located it (None: no entry; ...: located when needed)
ModelKind = str | None | EllipsisType


def calibrations_path(directory: str | Path | None = None) -> Path:
    """The file ``save_calibration`` writes: in ``directory``, else in the user zoo (PredictorError when the
    user zoo is the shipped one, which is read-only)."""
    root = Path(directory) if directory is not None else writable_zoo_dir()
    return root / CALIBRATIONS_NAME


def calibration_files(directory: str | Path | None = None) -> list[Path]:
    """The files calibrations are read from, the first holding a key winning: ``directory``'s alone, else
    ``zoo_calibration_files()``."""
    if directory is not None:
        return [Path(directory) / CALIBRATIONS_NAME]
    return [path for _, path in zoo_calibration_files()]


def zoo_calibration_files(user_dir: str | Path | None = None) -> list[tuple[str, Path]]:
    """``(zoo, file)`` of the user zoo's calibrations (``user_dir``, else ``$CROWDMPC_ZOO``'s), then the
    shipped zoo's (once when they are the same directory), the first holding a key winning."""
    user = user_zoo_dir(user_dir)
    roots = (
        [(SHIPPED, checkpoints_dir())] if is_shipped(user) else [(USER, user), (SHIPPED, checkpoints_dir())]
    )
    return [(zoo, root / CALIBRATIONS_NAME) for zoo, root in roots]


def read_calibration_file(path: Path) -> list[Calibration]:
    """Every block of one calibrations file; none where nothing has its name. Anything there but a regular
    file (or a link to one) is refused: taken for absent, it let the shipped blocks be used in silence."""
    if not os.path.lexists(path):
        return []
    if not path.is_file():  # before any open: opening a FIFO for reading waits for a writer
        why = f"not a regular file ({node_kind(path)}); the zoo's calibrations are read from a JSON file"
        raise PredictorError(f"{path}: {why} of that name: move this away")
    document = read_document(path, CALIBRATIONS_FORMAT, "crowdmpc calibrations file")
    version = document.get("version")
    if type(version) is not int or version != CALIBRATIONS_VERSION:  # type(): True and 1.0 are no version 1
        raise PredictorError(
            f'{path}: unsupported "version" {short_repr(version)}, expected {CALIBRATIONS_VERSION}'
        )
    blocks = document.get("calibrations", [])
    if not isinstance(blocks, list):
        raise PredictorError(f'{path}: "calibrations" must be a list of blocks, got {blocks!r}')
    result = [Calibration.from_json(b, f"{path}: calibrations[{i}]") for i, b in enumerate(blocks)]
    seen: dict[tuple[str, str], list[Calibration]] = {}  # (predictor, source) -> its blocks so far
    for i, block in enumerate(result):
        # two blocks for one key would make find_calibration's answer depend on their order
        same = seen.setdefault((block.predictor, block.source), [])
        if any(other.same_key(block) for other in same):
            raise PredictorError(
                f"{path}: calibrations[{i}] repeats predictor {block.predictor!r}, source {block.source!r}, "
                f"alpha={alpha_text(block.alpha)}{_behind(*block.key()[3:])}; keep one of them"
            )
        same.append(block)
    return result


def stored_calibrations(directory: str | Path | None = None) -> list[tuple[Path, Calibration]]:
    """``(file, block)`` for every block in force (``calibration_files``): a user block hides the shipped
    block of its key."""
    return blocks_in_force(calibration_files(directory))


def blocks_in_force(files: Sequence[Path]) -> list[tuple[Path, Calibration]]:
    """``(file, block)`` for every block of ``files`` but those a block of the same key in an earlier file
    hides."""
    found: list[tuple[Path, Calibration]] = []
    by_key: dict[tuple[str, str], list[Calibration]] = {}  # (predictor, source) -> blocks found
    for path in files:
        for block in read_calibration_file(path):
            same = by_key.setdefault((block.predictor, block.source), [])
            if not any(other.same_key(block) for other in same):
                found.append((path, block))
                same.append(block)
    return found


def read_calibrations(directory: str | Path | None = None) -> list[Calibration]:
    """Every block in force: ``directory``'s, else the user zoo's, then the shipped ones not replaced."""
    return [block for _, block in stored_calibrations(directory)]


def save_calibration(
    block: Calibration, directory: str | Path | None = None, check: Callable[[], None] | None = None
) -> Path:
    """Store ``block`` in ``calibrations_path(directory)``: ``save_calibrations`` of it alone."""
    return save_calibrations([block], directory, check)


def save_calibrations(
    blocks: Sequence[Calibration],
    directory: str | Path | None = None,
    check: Callable[[], None] | None = None,
) -> Path:
    """Store ``blocks`` in ``calibrations_path(directory)`` (the user zoo by default, never the shipped zoo),
    each replacing that file's block with the same key (``Calibration.key``); written atomically, all in one
    write (one at a time, a Ctrl-C or refusal between two left some of a run's blocks stored, mixed with
    other runs'). ``check()`` runs under the lock, on the file as this write finds it, and what it raises
    stops the write."""
    path = calibrations_path(directory)
    for i, block in enumerate(blocks):  # both written, the file is refused by every read that follows
        if any(other.same_key(block) for other in blocks[:i]):
            raise PredictorError(
                f"blocks[{i}] repeats predictor {block.predictor!r}, source {block.source!r}, "
                f"alpha={alpha_text(block.alpha)}{_behind(*block.key()[3:])}: store one block per key"
            )
    # under the zoo's lock: two calibrations that both read the old file would each write back only their own
    with zoo_lock(path.parent):
        if check is not None:
            check()
        kept = [b for b in read_calibration_file(path) if not any(b.same_key(new) for new in blocks)]
        write_blocks(path, [*kept, *blocks])
    return path


def undo_calibrations(
    stored: Sequence[Calibration], earlier: Sequence[Calibration] | None, directory: str | Path | None = None
) -> Path:
    """Take back the blocks ``stored`` by one run: each key's block in ``earlier`` (the file's blocks before
    that run, None: there was no file; none of a key: its block is dropped) where the file still holds the
    one that run stored. Blocks another run stored meanwhile, of other keys or over these, stay."""
    path = calibrations_path(directory)
    ours = {_as_stored(b) for b in stored}
    with zoo_lock(path.parent):
        current = read_calibration_file(path)
        undone = [b for b in current if _as_stored(b) in ours]
        kept = [b for b in current if _as_stored(b) not in ours]
        back = [e for e in earlier or () if any(e.same_key(u) for u in undone)]
        if earlier is None and not kept:  # this run made the file
            path.unlink(missing_ok=True)
        else:
            write_blocks(path, [*kept, *back])
    return path


def _as_stored(block: Calibration) -> str:
    """``block`` as the file holds it: a block made in this process may keep tuples in its details (a
    closed-loop block's ``humans``) where the one read back has lists, and the two must compare equal."""
    return json.dumps(block.to_json(), sort_keys=True, allow_nan=False)


def _file_order(block: Calibration) -> tuple[str, str, float, float, bool]:
    """``block.key()`` as a sort key: the block with every human in view before those behind sensors, the
    tracker's track lengths given before not."""
    return block.predictor, block.source, block.alpha, block.sensor_range or 0.0, not block.sensor_tracks


def _behind(sensor_range: float | None, tracks: bool = True) -> str:
    """`` behind a 3 m sensor`` (`` without track lengths`` after it where ``tracks`` is False: its tracker
    reported none) for a block made behind one, nothing for one with every human in view."""
    if sensor_range is None:
        return ""
    return f" behind a {sensor_range:g} m sensor" + ("" if tracks else " without track lengths")


def write_blocks(path: Path, blocks: list[Calibration]) -> None:
    """Write ``blocks`` as ``path``'s whole content (the caller holds the zoo's lock)."""
    document = {
        "format": CALIBRATIONS_FORMAT,
        "version": CALIBRATIONS_VERSION,
        "calibrations": [b.to_json() for b in sorted(blocks, key=_file_order)],
    }
    write_text_durably(path, json.dumps(document, indent=2, allow_nan=False) + "\n")


def current_sha256(predictor: str, directory: str | Path | None = None) -> str | None:
    """The sha256 of ``predictor``'s weights in the zoo at ``directory``; None for a weightless predictor."""
    from predictors.registry import PREDICTORS

    if predictor in PREDICTORS:
        return None
    entries = read_manifest(directory)
    if predictor not in entries:
        raise UnknownPredictor(predictor, sorted(PREDICTORS) + sorted(entries))
    return entries[predictor].sha256


def recalibrate_command(
    predictor: str,
    source: str,
    alpha: float,
    sensor_range: float | None = None,
    sensor_tracks: bool = True,
    kind: str | None | EllipsisType = ...,
) -> str:
    """The ``crowdmpc calibrate`` command line that makes the block of ``(predictor, source, alpha)``, behind
    a sensor of ``sensor_range`` m (reporting no track lengths unless ``sensor_tracks``) where given.
    ``kind``: the model kind of the zoo entry ``predictor`` loads, as the caller located it (None: no zoo
    entry; ``...``: located here, reading the manifest)."""
    sensor = _sensor_options(sensor_range, sensor_tracks)
    return (
        f"{_crowdmpc(predictor, kind)} calibrate --predictor {predictor} --source {source} "
        f"--alpha {alpha_text(alpha)}{sensor}"
    )


def _crowdmpc(predictor: str, kind: str | None | EllipsisType = ...) -> str:
    """``crowdmpc``, with the ``--plugin`` a zoo model of a plugin net needs to load (the command said to run
    failed with "a plugin that is not registered" without it), of the model ``kind`` a caller located
    (``...``: located here)."""
    from predictors.models import PLUGIN_PATTERN
    from predictors.zoo import locate

    if kind is ...:
        try:
            located = locate(predictor)
        except PredictorError:
            return "crowdmpc"
        kind = located.entry.model if located is not None else None
    model = kind or ""
    return f"crowdmpc --plugin {model}" if PLUGIN_PATTERN.fullmatch(model) else "crowdmpc"


def _sensor_options(sensor_range: float | None, sensor_tracks: bool) -> str:
    """`` --sensor-range 3`` (and `` --no-sensor-tracks``) for a block made behind a sensor, else nothing."""
    if sensor_range is None:
        return ""
    return f" --sensor-range {sensor_range:g}" + ("" if sensor_tracks else " --no-sensor-tracks")


# the closed-loop settings a block's details record, as calibrate's options: the episodes a block was made
# on, and so the humans its margins cover (pipelines/experiments/calibrate.py, ClosedLoopPlan)
MADE_WITH: Final[tuple[str, ...]] = (
    "episodes",
    "seed",
    "humans",
    "controller",
    "profile",
    "visibility",
    "near",
)


def made_with(block: Calibration) -> dict[str, str]:
    """``MADE_WITH``'s settings ``block``'s details record, each as calibrate's option takes it (``humans``
    ``5,6``, ``near`` ``inf`` for everyone scored); none for a real block, whose scenes were recorded."""
    details = block.details if block.source == "closed-loop" else {}
    found = {key: details[key] for key in MADE_WITH if key in details}
    if isinstance(found.get("humans"), list | tuple):
        found["humans"] = ",".join(str(h) for h in found["humans"])
    if "near" in found and not isinstance(found["near"], str):
        found["near"] = "inf" if found["near"] is None else f"{found['near']:g}"  # null: everyone scored
    return {key: str(value) for key, value in found.items()}


def calibrate_command(
    block: Calibration,
    alphas: Sequence[float] = (),
    *,
    kind: str | None | EllipsisType = ...,
    view: tuple[float | None, bool] | None = None,
    **changed: object,
) -> str:
    """The ``crowdmpc calibrate`` command line that makes ``block`` again, at ``alphas`` (default its own)
    with the settings it records (``made_with``) but those ``changed`` (``episodes=400``), behind the sensor
    of ``view`` (sensor range, track lengths given; None: the block's own); ``kind`` as
    ``recalibrate_command`` takes it."""
    alpha = ",".join(alpha_text(a) for a in alphas or (block.alpha,))
    settings = made_with(block) | {key: str(value) for key, value in changed.items()}
    return (
        f"{_crowdmpc(block.predictor, kind)} calibrate --predictor {block.predictor} --source {block.source} "
        f"--alpha {alpha}"
        + "".join(f" --{key} {value}" for key, value in settings.items())
        + _sensor_options(*(view or (block.sensor_range, block.sensor_tracks)))
    )


def find_calibration(
    predictor: str,
    source: str,
    alpha: float,
    directory: str | Path | None = None,
    sha256: str | None | EllipsisType = ...,
    sensor_range: float | None = None,
    sensor_tracks: bool = True,
) -> Calibration:
    """The stored block for (predictor, source, alpha) that a controller behind a sensor of ``sensor_range``
    m (None: seeing every human), given the track lengths or not (``sensor_tracks``), plans with, checked
    against the current weights.

    Of the blocks made behind different sensors, the one made behind ``sensor_range`` is taken (with the
    track lengths as the run has them, else without), else the one made with every human in view, else the
    one behind the nearest range (the notes of
    ``pipelines.commands.calibration_notes`` say when the view differs). ``sha256`` is the sha256 the weights
    have now (None for a weightless predictor); the default ``...`` reads it from the zoo manifest in
    ``directory``. A block made for other weights is refused.
    """
    return locate_calibration(predictor, source, alpha, directory, sha256, sensor_range, sensor_tracks)[1]


def locate_calibration(
    predictor: str,
    source: str,
    alpha: float,
    directory: str | Path | None = None,
    sha256: str | None | EllipsisType = ...,
    sensor_range: float | None = None,
    sensor_tracks: bool = True,
    kind: ModelKind = ...,
    stored: Sequence[tuple[Path, Calibration]] | None = None,
) -> tuple[Path, Calibration]:
    """``(file, block)``: the block ``find_calibration`` gives and the calibrations file holding it, which
    tells a user's block from a shipped one (``calibration_zoo``). ``kind``: as ``recalibrate_command``
    takes it, for the command a refusal quotes. ``stored``: ``stored_calibrations(directory)`` as a caller
    read it once for several lookups (None: read here)."""
    check_alpha(alpha)
    if source not in SOURCES:
        raise PredictorError(f"unknown calibration source {source!r}; choose from {list(SOURCES)}")
    stored = stored_calibrations(directory) if stored is None else stored
    wanted = (sensor_range, sensor_tracks)
    found = [(path, b) for path, b in stored if b.matches(predictor, source, alpha)]
    if not found:
        others = sorted(b.alpha for _, b in stored if b.predictor == predictor and b.source == source)
        have = f" (it has alpha {', '.join(alpha_text(a) for a in sorted(set(others)))})" if others else ""
        files = " or ".join(str(p) for p in calibration_files(directory))
        raise PredictorError(
            f"no {source} calibration at alpha={alpha_text(alpha)} for predictor {predictor!r} in "
            f"{files}{have}; run: {recalibrate_command(predictor, source, alpha, *wanted, kind=kind)}"
        )
    path, block = min(found, key=lambda found: view_distance(found[1].key()[3:], wanted))
    expected = current_sha256(predictor, directory) if sha256 is ... else sha256
    if block.predictor_sha256 != expected:
        view, why = remaking_view(block, wanted)
        command = recalibrate_command(predictor, source, alpha, *view, kind=kind)
        behind = _behind(block.sensor_range, block.sensor_tracks)
        raise PredictorError(
            f"{path}: the {source} calibration at alpha={alpha_text(alpha)}{behind} of "
            f"predictor {predictor!r} was made for weights sha256 {block.predictor_sha256}, but the weights "
            f"now have sha256 {expected}; the weights changed since calibration, recalibrate: {command}{why}"
        )
    return path, block


def calibration_zoo(path: Path) -> str:
    """``SHIPPED`` for a calibrations file of the shipped zoo, else ``USER`` (the user zoo's, or a directory
    a caller named)."""
    return SHIPPED if is_shipped(path.parent) else USER


def view_distance(
    made: tuple[float | None, bool], wanted: tuple[float | None, bool]
) -> tuple[int, float, bool, float]:
    """How far a block made behind ``made`` (range in m, None: every human in view; track lengths given) is
    from the view ``wanted``: the same view first, then the same range with the track lengths the other way,
    then every human in view, then the nearest range (for a ``wanted`` range None: the longest; of two as
    near, the shorter, whose margins are the wider: the safe side)."""
    (made_range, made_tracks), (wanted_range, wanted_tracks) = made, wanted
    if made == wanted:
        return 0, 0.0, False, 0.0
    if made_range == wanted_range:
        return 1, 0.0, False, 0.0
    if made_range is None:
        return 2, 0.0, False, 0.0
    near = -made_range if wanted_range is None else abs(made_range - wanted_range)
    return 3, near, made_tracks != wanted_tracks, made_range
