"""Which scenes ``crowdmpc train`` trains, validates and tests on: the prepared files of a protocol and
dataset, or explicit files; what a run records of that choice, and what a resume that types none of it takes
from its run (``take_run_data``)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any, Final

from pipelines.commands import check_data_files, path_arg
from pipelines.errors import PipelineError, print_note

# The protocols and test sequences of the commands' options (train, evaluate, zoo add), written here rather
# than imported from predictors.data.locate, whose numpy and trajnetplusplustools cost a parser 3 s; the same
# as locate's (tests/pipelines/test_protocol_names.py).
DATASET_SUFFIX: Final[dict[str, str]] = {"biwi_eth": "eth", "biwi_hotel": "hotel"}
DEFAULT_PROTOCOL, DEFAULT_DATASET = "paper", "biwi_eth"
PROTOCOLS: Final[tuple[str, ...]] = ("paper", "loo")
# the data options, as argparse names them; a resume that types none of them goes on with the run's
_OPTIONS: Final[tuple[str, ...]] = ("data_dir", "protocol", "dataset", "train", "val", "test")


def data_dir_option(parser: argparse.ArgumentParser) -> None:
    """--data-dir, where the prepared files are (train, evaluate): None by default, so that one typed with
    explicit files is told from $CROWDMPC_DATA and refused."""
    parser.add_argument(
        "--data-dir", type=path_arg, default=None, help="data directory (default: $CROWDMPC_DATA)"
    )


def dataset_option(parser: argparse.ArgumentParser) -> None:
    """--dataset, the protocol's test sequence (train, evaluate): None by default, as --data-dir."""
    parser.add_argument(
        "--dataset",
        default=None,
        choices=tuple(DATASET_SUFFIX),
        help=f"test sequence (default {DEFAULT_DATASET})",
    )


def data_options(parser: argparse.ArgumentParser) -> None:
    """Which scenes: prepared files by protocol and dataset, or explicit files."""
    # None by default, here and below: given with explicit --train/--val files, they are refused
    data_dir_option(parser)
    parser.add_argument(
        "--protocol",
        default=None,
        choices=PROTOCOLS,
        help=f"train/val/test files (default {DEFAULT_PROTOCOL})",
    )
    dataset_option(parser)
    parser.add_argument(
        "--train",
        nargs="+",
        type=path_arg,
        default=None,
        metavar="FILE",
        help="explicit training ndjson files instead of --protocol (needs --val)",
    )
    parser.add_argument(
        "--val",
        nargs="+",
        type=path_arg,
        default=None,
        metavar="FILE",
        help="explicit validation ndjson files, which choose the best epoch (with --train)",
    )
    parser.add_argument(
        "--test",
        nargs="+",
        type=path_arg,
        default=None,
        metavar="FILE",
        help="explicit test ndjson files scored after training (with --train and --val; default: none)",
    )


def resolve_files(args) -> tuple[dict[str, list[Path]], Path | None]:
    """The train/val/test files and the directory their names are relative to (None: as given)."""
    if args.test is not None and args.train is None and args.val is None:
        raise PipelineError("--test goes with --train and --val (explicit files replace --protocol)")
    if args.train is not None or args.val is not None:
        if not args.train or not args.val:
            raise PipelineError("--train and --val go together (explicit files replace --protocol)")
        files = {"train": list(args.train), "val": list(args.val), "test": list(args.test or [])}
        for split, paths in files.items():
            # twice, its scenes count twice, but the run's data record names it once: the same identity as a
            # run trained on it once, with other weights
            check_data_files(f"--{split}", paths)
        return files, None
    from predictors.data.locate import prepared_dir, protocol_files

    files = protocol_files(
        args.data_dir, args.protocol, args.dataset, progress=False if args.no_progress else None
    )
    return files, prepared_dir(args.data_dir)


def protocol_options(args: argparse.Namespace, explicit: bool, files: str = "--train/--val") -> None:
    """PipelineError when --protocol, --dataset or --data-dir are given with explicit --train/--val files,
    which replace the prepared files those options choose (they were ignored without a word, and the run
    recorded as "custom"). $CROWDMPC_DATA is no option typed, and passes. Their defaults are filled in by
    ``take_run_data``, once a resume has taken the run's. ``files``: the explicit files' options, as named
    (benchmarks/batching.py has --train alone)."""
    given = [
        option
        for option, value in (
            ("--protocol", args.protocol),
            ("--dataset", args.dataset),
            ("--data-dir", args.data_dir),
        )
        if value is not None
    ]
    if explicit and given:
        verb = "does" if len(given) == 1 else "do"
        raise PipelineError(
            f"{' and '.join(given)} {verb} not go with {files} (explicit files replace the prepared "
            "files of --protocol, --dataset and --data-dir); give one or the other"
        )


def check_data(files: dict[str, list[Path]], progress: bool | None = False) -> dict[Path, list[Any]]:
    """Every data file is read as the run will read it, and each split given holds scenes, before Lightning
    starts (its banner would come before the one-line error, and a half-made run folder after it). The
    training and validation files are loaded as the training data module loads them (``load_file_arrays``:
    training's scenes of exactly 21 steps, validation's last 21), which keeps them for it. The validation and
    test files are also read as the evaluation of the trained net reads them (scene length, frame rate,
    spacing): a file it refuses, such as a TrajNet++ test/ file without ground truth, was found only after
    training, with no metrics written. Returns those scenes by path, for that evaluation: each file is
    parsed once (the validation file was parsed three times, the test file twice). ``progress``: a bar while
    a file's scenes are built (None: on a terminal only), the first read of a large file being a minute of
    silence otherwise."""
    from predictors.data.validate import parse_ndjson
    from predictors.data.windows import Window, load_file_arrays
    from predictors.evaluate import eval_scenes_of

    evaluated: dict[Path, list[Any]] = {}
    for split, paths in files.items():
        held = []
        for path in paths:
            # a training file's arrays may come from the disk cache, unparsed; the evaluation's scenes may
            # not (a test file that is also the validation file has them already)
            content = None if split == "train" or path in evaluated else parse_ndjson(path)
            if content is not None:  # first: its message tells a test/ file without ground truth
                evaluated[path] = eval_scenes_of(content)
            if split != "train":
                held.append(len(evaluated[path]))
            if split != "test":
                window: Window = "whole" if split == "train" else "last"  # as the data module reads them
                held.append(len(load_file_arrays(path, window=window, progress=progress, content=content)))
        # an empty --test too: the run passed with its test metrics silently missing
        if paths and not any(held):
            names = ", ".join(str(p) for p in paths)
            raise PipelineError(f"--{split} {names}: holds no scenes; {split} needs at least one")
    return evaluated


def data_settings(args: argparse.Namespace, files: dict[str, list[Path]]) -> dict[str, Any]:
    """What the run records of its data choice besides its files (``train_resume.run_settings``):
    ``{"explicit": True}`` for --train/--val files, else the protocol and dataset, and the resolved data
    directory (``data_dir``, which a resume takes but does not compare: the same prepared files can come
    from two copies of the raw data, and the files are compared); and each file's content
    (``data_sha256``, by resolved path), which a resume must find unchanged (``check_resumed_data``)."""
    hashes = {"data_sha256": data_hashes(files)}
    if args.train is not None or args.val is not None:
        return {"data": {"explicit": True}, **hashes}
    from predictors.data.locate import resolve_data_dir

    return {
        "data": {"protocol": args.protocol, "dataset": args.dataset},
        "data_dir": str(resolve_data_dir(args.data_dir).resolve()),
        **hashes,
    }


def data_hashes(files: dict[str, list[Path]]) -> dict[str, str]:
    """Each data file's sha256 by its resolved path (a file in two splits once)."""
    from predictors.hashing import sha256_file

    return {str(p.resolve()): sha256_file(p) for paths in files.values() for p in paths}


def note_shared_data(files: dict[str, list[Path]], hashes: dict[str, str]) -> None:
    """A note when a --val file holds the same bytes as a --train file, or a --test file as a --train or
    --val file, by name or as a copy: the best epoch is then chosen, and the validation metrics the zoo
    records measured, on training data; a "test" ADE, which metrics.json and the zoo record as held out, on
    data the net trained on or chose its epoch by. (A --val that is the training file went unsaid, for the
    small checks that do it on purpose, though data/README.md said it is noted: a note costs them a line.)"""
    consequence = {
        "val": "the best epoch is chosen, and its validation metrics measured, on training data",
        "test": "its test metrics are not on held-out data",
    }
    for split, earlier in (("val", ("train",)), ("test", ("val", "train"))):
        seen = {hashes[str(p.resolve())]: (s, p) for s in earlier for p in files[s]}
        for path in files[split]:
            sha = hashes[str(path.resolve())]
            if sha not in seen or not path.stat().st_size:  # two empty files are no shared data
                continue
            other_split, first = seen[sha]
            other = f"--{other_split}" if first.resolve() == path.resolve() else f"--{other_split} {first}"
            print_note(
                f"note: --{split} {path} holds the same data as {other} (sha256 {sha[:12]}…): "
                f"{consequence[split]}"
            )


def check_resumed_data(out: Path, recorded: dict[str, Any] | None, hashes: dict[str, str]) -> None:
    """PipelineError when a data file of the run in ``out`` (same path, ``recorded``: its settings) holds
    other content than when the run started: the resume trained on the new content without a word, and the
    run's metrics and zoo entry recorded only the new hash, for weights trained on both. A run from before
    the hashes were recorded has none to compare."""
    held = recorded.get("data_sha256") if recorded is not None else None
    if not isinstance(held, dict):
        return
    for path, sha in hashes.items():
        before = held.get(path)
        if isinstance(before, str) and before != sha:
            raise PipelineError(
                f"--resume: data file {path} has changed since the run in {out} started (sha256 "
                f"{before} then, {sha} now); restore that file, or start a new run with another "
                "--out"
            )


def take_run_data(args: argparse.Namespace, recorded: dict[str, Any] | None, out: Path) -> list[str]:
    """The defaults of --protocol and --dataset, but on a resume that types no data option the run's
    (``recorded``: its settings, ``data_settings``): its --train/--val/--test files, or its protocol and
    dataset, and its data directory where neither --data-dir nor $CROWDMPC_DATA names one; one that gives
    other prepared files than the run's (in ``out``) is refused before anything is prepared. Returns what
    was taken that a new run would not have, as a resume names it. A run from before its data choice was
    recorded, or one a data option is typed for, takes nothing: its files are compared with those the
    options choose (``check_resumed_settings``), and a mismatch is refused."""
    taken = _taken_data(args, recorded)
    args.protocol = args.protocol or DEFAULT_PROTOCOL
    args.dataset = args.dataset or DEFAULT_DATASET
    if args.resume and recorded is not None and args.train is None and args.val is None:
        _check_resumed_data_dir(args, recorded, out)
    return taken


def _check_resumed_data_dir(args: argparse.Namespace, recorded: dict[str, Any], out: Path) -> None:
    """PipelineError when the data directory a resume reads (--data-dir, else $CROWDMPC_DATA, which the
    run's does not override) gives other prepared files than the run trained on (``recorded``: its settings):
    the resume prepared that directory's raw data first (minutes), then refused the files in a line cut
    short that named no data directory. Said before anything is prepared; the same data in another folder,
    which gives the same prepared files, passes."""
    from predictors.data.locate import DATA_ENV, prepared_location, resolve_data_dir

    held, files = recorded.get("data_dir"), recorded.get("files")
    tested = _paths(files.get("test")) if isinstance(files, dict) else []
    if not isinstance(held, str) or not held or len(tested) != 1:  # no protocol run's record
        return
    run_root = tested[0].parent.parent  # a protocol's test file: PREPARED/test/NAME.ndjson
    directory = prepared_location(args.data_dir)
    if directory is None or resolve_data_dir(args.data_dir).resolve() == Path(held):
        return  # nothing to tell yet (prepared_dir says why), or the run's own directory
    if directory.resolve() == run_root:
        return
    source = (
        f"--data-dir {args.data_dir}" if args.data_dir is not None else f"${DATA_ENV} {os.environ[DATA_ENV]}"
    )
    raise PipelineError(
        f"--resume: {out} was trained on the prepared data in {run_root} (data directory {held}); "
        f"{source} gives {directory}: resume with --data-dir {held}"
    )


def _taken_data(args: argparse.Namespace, recorded: dict[str, Any] | None) -> list[str]:
    from predictors.data.locate import DATA_ENV

    data = recorded.get("data") if args.resume and recorded is not None else None
    if not isinstance(data, dict) or any(getattr(args, option) is not None for option in _OPTIONS):
        return []
    if data.get("explicit") is True:
        files = recorded.get("files") if recorded is not None else None
        if not isinstance(files, dict) or not all(_paths(files.get(split)) for split in ("train", "val")):
            return []
        args.train, args.val = (_paths(files[split]) for split in ("train", "val"))
        args.test = _paths(files.get("test")) or None
        return ["data files"]
    taken = []
    for option, choices, default in (
        ("protocol", PROTOCOLS, DEFAULT_PROTOCOL),
        ("dataset", tuple(DATASET_SUFFIX), DEFAULT_DATASET),
    ):
        if data.get(option) in choices:
            setattr(args, option, data[option])
            if data[option] != default:
                taken.append(f"{option} {data[option]}")
    held = recorded.get("data_dir") if recorded is not None else None
    if isinstance(held, str) and held and not os.environ.get(DATA_ENV):
        args.data_dir = held
        taken.append(f"data directory {held}")
    return taken


def _paths(recorded: Any) -> list[Path]:
    """A recorded list of file names as paths; empty for anything else (a damaged settings file)."""
    if not isinstance(recorded, list) or not all(isinstance(p, str) and p for p in recorded):
        return []
    return [Path(p) for p in recorded]
