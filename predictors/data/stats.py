"""Per-file statistics of TrajNet++ ndjson files (``crowdmpc data stats``)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from predictors.data.trajnet_io import shown_scenes
from predictors.data.validate import parse_ndjson
from predictors.errors import DatasetFormatError, PredictorError
from predictors.text_table import aligned_lines, counted


@dataclass(frozen=True)
class FileStats:
    path: Path
    scenes: int
    tracks: int  # distinct track rows (pedestrian and frame): an identical repeated row is one position
    repeated: int  # track records that repeat an earlier one (the Reader keeps one)
    pedestrians: int  # distinct pedestrian ids
    agents_min: int  # agents per scene, as Reader.paths_to_xy returns them (primary included)
    agents_mean: float
    agents_max: int
    types: tuple[int, int, int, int]  # scenes of TrajNet++ type I, II, III, IV (untagged scenes not counted)
    fps: tuple[float | None, ...] = ()  # the scenes' distinct frame rates, None for scenes without one
    untagged: int = 0  # scenes without a tag (tag 0: uncategorised; _untagged_cause says who writes them)
    odd_tags: int = 0  # scenes whose tag is no TrajNet++ type: [2.0, []], [5, []], "III" (the Reader's any)
    odd_example: str = ""  # the first of those tags, as the file holds it


def file_stats(path: str | Path, *, progress: bool | None = False) -> FileStats:
    """The statistics of one file; ``progress``: a bar over its scenes (None: on a terminal only). Building
    a scene costs time in its rows: a file of dense crowds (240 agents a scene) takes a minute or more."""
    content = parse_ndjson(path)  # once: the scenes are built from the rows it checked
    summary = content.summary
    sizes: list[int] = []  # a scene at a time: a large file's scenes are GBs as arrays
    types = [0, 0, 0, 0]
    untagged, odd = 0, []
    for scene in shown_scenes(content, progress):
        sizes.append(scene.xy.shape[1])
        kind = scene_type(scene.tag)
        if kind is not None:
            types[kind - 1] += 1
        elif scene.tag == 0 and not isinstance(scene.tag, bool):
            untagged += 1
        else:
            odd.append(scene.tag)
    agents = np.asarray(sizes or [0])
    distinct = len({(row.frame, row.pedestrian) for row in content.tracks})
    return FileStats(
        path=Path(path),
        scenes=len(sizes),
        tracks=distinct,
        repeated=summary.n_tracks - distinct,
        pedestrians=len(summary.pedestrians),
        agents_min=int(agents.min()),
        agents_mean=float(agents.mean()) if sizes else 0.0,
        agents_max=int(agents.max()),
        types=(types[0], types[1], types[2], types[3]),
        fps=tuple(sorted({row.fps for row in content.scenes}, key=lambda fps: (fps is None, fps or 0))),
        untagged=untagged,
        odd_tags=len(odd),
        odd_example=_shortened(json.dumps(odd[0])) if odd else "",
    )


def _shortened(text: str, limit: int = 60) -> str:
    """``text`` cut to ``limit`` characters with "...": a tag may be any JSON, a whole scene's worth."""
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


def scene_type(tag: object) -> int | None:
    """The TrajNet++ type (1..4 for I..IV) of a scene's tag ``[type, [sub-types]]``; None for an untagged
    scene or any other tag. The Reader passes the tag through unchecked: a float type (2.0) used to end
    `data stats` in a TypeError, and ``true`` (== 1 in Python) counted as type I."""
    if not isinstance(tag, list) or not tag:
        return None
    kind = tag[0]
    if isinstance(kind, bool) or not isinstance(kind, int) or not 1 <= kind <= 4:
        return None
    return kind


def ndjson_files(directory: str | Path) -> list[Path]:
    """Every ``*.ndjson`` under ``directory`` (recursively), sorted; a file alone, as train and evaluate
    take them."""
    directory = Path(directory)
    if directory.is_file():
        return [directory]
    if not directory.is_dir():
        raise PredictorError(f"{directory} is neither an ndjson file nor a directory")
    matches = sorted(directory.rglob("*.ndjson"))
    for path in matches:
        # left out, the folder's statistics described fewer files than it holds, without a word; evaluate
        # and train refuse such a file too (validate.require_file)
        if not (path.is_file() or path.is_dir()):
            what = (
                f"a symbolic link to {os.readlink(path)}, which does not exist"
                if path.is_symlink()
                else "not a regular file (a pipe, a socket or a device)"
            )
            raise DatasetFormatError(
                path, None, f"{what}, named *.ndjson under {directory}; remove it or make it an ndjson file"
            )
    files = [p for p in matches if p.is_file()]
    if not files:
        raise PredictorError(f"no .ndjson files under {directory}")
    return files


def stats_report(path: str | Path) -> tuple[str, list[str]]:
    """``data stats`` of an ndjson file or of every one under a folder: the table, and its notes (stderr).
    A bar over each file's scenes on a terminal only, so that a piped table stays clean."""
    stats = [file_stats(f, progress=None) for f in ndjson_files(path)]
    return format_table(stats, root=path), repeated_notes(stats) + tag_notes(stats)


def repeated_notes(stats: list[FileStats]) -> list[str]:
    """A note for each file with repeated track rows, which the tracks column counts once."""
    return [
        f"note: {s.path}: {counted(s.repeated, 'track row')} "
        f"repeat{'s' * (s.repeated == 1)} an earlier one (same "
        "pedestrian and frame); counted once"
        for s in stats
        if s.repeated
    ]


def tag_notes(stats: list[FileStats]) -> list[str]:
    """What the types column leaves out: a note for each file with tags that are no TrajNet++ type (a
    hand-made or foreign file; they were counted nowhere, unsaid), and one for the untagged scenes of all."""
    notes = [
        f"note: {s.path}: {counted(s.odd_tags, 'scene')} tagged with no TrajNet++ type "
        f"(an integer 1-4), e.g. {s.odd_example}: left out of the types column"
        for s in stats
        if s.odd_tags
    ]
    causes: dict[str, list[FileStats]] = {}  # one note per cause, in the order of the files
    for s in stats:
        if s.untagged:
            causes.setdefault(_untagged_cause(s), []).append(s)
    for cause, files in causes.items():
        n = sum(s.untagged for s in files)
        where = str(files[0].path) if len(files) == 1 else f"{len(files)} files"
        notes.append(
            f"note: {counted(n, 'scene')} in {where} {'are' if n != 1 else 'is'} untagged ({cause}): "
            "left out of the types column"
        )
    return notes


def _untagged_cause(s: FileStats) -> str:
    """Why a file's scenes carry no type (tag 0, or none, which the Reader reads as 0): blaming `data
    prepare --no-tags` misled for a TrajNet++ test file, whose scenes hold only the observed steps and are
    tagged 0 by its converter (trajnetplusplusdataset's ``Scenes.rows_to_file``): the ground truth, which the
    tags are computed from, is withheld; its test_private/ twin holds both. ``s``: a file with untagged
    scenes."""
    from predictors.data.locate import load_manifest

    split = s.path.parent
    manifest = load_manifest(split.parent)
    if manifest is not None and f"{split.name}/{s.path.name}" in manifest.get("files", {}):
        parameters = manifest.get("parameters")
        if isinstance(parameters, dict) and parameters.get("categorized") is False:
            return "`data prepare --no-tags` wrote them so"
    elif "test" in (split.name, split.parent.name) and s.untagged == s.scenes:  # test/real_data/NAME.ndjson
        return (
            "a TrajNet++ test file tags every scene 0: its ground truth is withheld, and the tags with it; "
            "test_private/ holds both"
        )
    return "tag 0 or none: uncategorised, as `data prepare --no-tags` and TrajNet++'s test files write them"


def _shown_fps(fps: tuple[float | None, ...]) -> str:
    """The frame rates of a file's scenes ("2.5", "2.5,10", "none"): a file at another rate than 2.5 fps
    is refused by train and evaluate, and one without a rate is read as 2.5 fps."""
    return ",".join("none" if f is None else f"{f:g}" for f in fps) or "-"


def format_table(stats: list[FileStats], root: str | Path | None = None) -> str:
    """A plain-text table, one row per file plus the totals; ``root``: the folder (or the one file) the
    names are relative to."""
    header = (
        "file",
        "scenes",
        "tracks",
        "peds",
        "agents/scene min",
        "mean",
        "max",
        "types I/II/III/IV",
        "fps",
    )
    root = Path(root).parent if root is not None and Path(root).is_file() else root
    rows = []
    for s in stats:
        name = str(s.path.relative_to(root)) if root is not None else str(s.path)
        rows.append(
            (
                name,
                str(s.scenes),
                str(s.tracks),
                str(s.pedestrians),
                str(s.agents_min),
                f"{s.agents_mean:.1f}",
                str(s.agents_max),
                "/".join(map(str, s.types)),
                _shown_fps(s.fps),
            )
        )
    if len(stats) > 1:
        n = sum(s.scenes for s in stats)
        mean = sum(s.agents_mean * s.scenes for s in stats) / max(n, 1)
        types = [sum(s.types[k] for s in stats) for k in range(4)]
        # a file without scenes reports 0 agents, which is no scene's minimum
        with_scenes = [s for s in stats if s.scenes] or stats
        rows.append(
            (
                "total",
                str(n),
                str(sum(s.tracks for s in stats)),
                "-",
                str(min(s.agents_min for s in with_scenes)),
                f"{mean:.1f}",
                str(max(s.agents_max for s in stats)),
                "/".join(map(str, types)),
                _shown_fps(
                    tuple(sorted({f for s in stats for f in s.fps}, key=lambda f: (f is None, f or 0)))
                ),
            )
        )
    return "\n".join(aligned_lines(header, rows))
