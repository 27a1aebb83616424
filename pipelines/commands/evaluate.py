"""``crowdmpc evaluate``: TrajNet++ metrics (ADE, FDE, Col-I, Col-II, top-k) of a predictor on a split."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Final

from pipelines.commands import check_data_files, check_writable, path_arg, write_output
from pipelines.commands.standard_output import is_stdout, json_on_stdout, json_path, shown
from pipelines.commands.train_data import (
    DEFAULT_DATASET,
    DEFAULT_PROTOCOL,
    PROTOCOLS,
    data_dir_option,
    dataset_option,
)
from pipelines.errors import PipelineError, print_note
from pipelines.plain_json import plain

if TYPE_CHECKING:
    from predictors.evaluate import EvalConfig, EvalScene
    from predictors.manifest import ZooEntry

EPILOG = """examples:
  crowdmpc evaluate --predictor constant_velocity --dataset biwi_eth --split test
  crowdmpc evaluate --predictor constant_velocity --data-dir data/prepared --protocol loo \\
      --json runs/cv_loo.json
  crowdmpc evaluate --predictor social_lstm_eth --test my_data/test_a.ndjson my_data/test_b.ndjson

protocols (data/README.md):
  paper  train = ETH + Hotel train splits, val = their val splits, test = ETH test split
  loo    train = zara01, zara03, students001, students003 (TrajNet++) + Hotel train split,
         val = Hotel val split, test = the same ETH test split

--test FILE.. scores your own TrajNet++ ndjson files instead (scenes of 9 + 12 steps at 2.5 fps, the last
21 steps of a longer scene; data/README.md); --data-dir, --protocol, --dataset and --split choose the
prepared files and do not go with it.

metrics (TrajNet++'s, of each scene's primary pedestrian; data/README.md):
  ADE, FDE     average and final displacement error over the 12 predicted steps, m
  Col-I        % of scenes where the primary's prediction collides with a neighbour's prediction
  Col-II       % of scenes where it collides with a neighbour's true path

A zoo model whose config reads fewer observed steps (obs_len 3) is given the last 3 of the 9 and the people
seen in them, as TrajNet++'s baselines give such a model; its Col-I then counts only the scenes whose every
neighbour seen in the 9 steps it predicted (starred, and said under the table).
"""


# Top-k draws K futures of every agent of a scene at once. The literature's K is 20; 1000 already takes
# minutes and 1 GiB on the ETH test split (social_gan_eth, 2 cores); 10^9 asked numpy for 894 GiB.
MAX_TOP_K: Final[int] = 1000


def counted(least: int, most: int | None = None) -> Callable[[str], int]:
    """An argparse type: an integer in ``least..most`` (no upper bound when ``most`` is None)."""
    expected = f"an integer in {least}..{most}" if most is not None else f"an integer >= {least}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text[:40]!r}") from None
        if value < least or (most is not None and value > most):
            shown = text if len(text) <= 40 else f"{text[:37]}..."
            raise argparse.ArgumentTypeError(f"expected {expected}, got {shown}")
        return value

    return parse


def seed_arg(text: str) -> int:
    """An argparse type: a seed in every command's range, 0..``pipelines.config.settings.MAX_SEED`` (TOML's
    largest integer, where a run's config records it): `data prepare` took -1 and `data synth` 10^22, seeds
    that no other command takes."""
    from pipelines.config.settings import MAX_SEED

    value = counted(0)(text)
    if value > MAX_SEED:
        given = text if len(text) <= 40 else f"{text[:37]}..."
        raise argparse.ArgumentTypeError(f"must be at most 2**63 - 1 (TOML's largest integer), got {given}")
    return value


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="ADE/FDE/Col-I/Col-II of a predictor on TrajNet++ scenes",
        description="Evaluate a registered predictor on TrajNet++ scenes: 9 observed -> 12 predicted steps, "
        "metrics of the primary pedestrian per file and overall.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--predictor",
        required=True,
        help="registered predictor or model-zoo name (shipped or user zoo; a plugin's model needs "
        "crowdmpc --plugin module:NetClass evaluate ...)",
    )
    # defaults filled in by _choose_files: None tells an option typed from its default, which --test refuses
    data_dir_option(parser)
    dataset_option(parser)
    parser.add_argument(
        "--split", default=None, choices=("train", "val", "test"), help="split to score (default test)"
    )
    parser.add_argument(
        "--protocol",
        default=None,
        choices=PROTOCOLS,
        help=f"which files form the split (default {DEFAULT_PROTOCOL})",
    )
    parser.add_argument(
        "--test",
        nargs="+",
        type=path_arg,
        default=None,
        metavar="FILE",
        help="score these TrajNet++ ndjson files (e.g. your own data) instead of a protocol's split",
    )
    parser.add_argument(
        "--top-k",
        type=counted(1, MAX_TOP_K),
        default=None,
        metavar="K",
        help=f"top-K ADE/FDE for sampling models (1..{MAX_TOP_K})",
    )
    parser.add_argument("--seed", type=seed_arg, default=0, help="seed for sampling models (default 0)")
    parser.add_argument(
        "--json",
        type=json_path,
        default=None,
        metavar="FILE",
        help="also write the results as JSON (-: standard output)",
    )
    parser.add_argument(
        "--no-progress", action="store_true", help="no progress bar (drawn on a terminal only)"
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        return _evaluate(args)


def _evaluate(args: argparse.Namespace) -> int:
    from pipelines.plugins import code_with_plugins
    from predictors.data.locate import prepared_dir, protocol_files
    from predictors.evaluate import EvalConfig, check_dataset_predictor, evaluate_scenes, format_table
    from predictors.registry import PREDICTORS, load_predictor, loaded_sha256
    from predictors.zoo import load_located, locate

    check_writable(args.json, "--json", json_only=True)
    _choose_files(args)
    config = EvalConfig(top_k=args.top_k, seed=args.seed)
    from pipelines.commands.quick_check_notes import quick_check_note
    from pipelines.commands.simulate_checks import zoo_notes

    # the entry the name loads (none for a built-in: constant velocity, the oracle), read once so that the
    # notes, the sha256 and protocol recorded are the scored weights', whatever a `zoo add --replace` puts in
    # meanwhile
    located = None if args.predictor in PREDICTORS else locate(args.predictor)
    # before the load: an edited plugin whose weights no longer fit said why only in simulate
    for note in zoo_notes(args.predictor, None if located is None else located.entry):
        print_note(note)
    predictor = load_predictor(args.predictor) if located is None else load_located(located)
    progress = False if args.no_progress else None  # None: a bar on a terminal only
    if args.test is not None:
        files, root = {"test": list(args.test)}, None
    else:
        files = protocol_files(args.data_dir, args.protocol, args.dataset, progress=progress)
        root = prepared_dir(args.data_dir)
    check_dataset_predictor(predictor)  # before the files are read
    loaded = _scenes(args, files[args.split], config, root)
    entry = None if located is None else located.entry
    quick = quick_check_note(args.predictor, entry)  # once the model and the files are taken, not before
    if quick is not None:
        print_note(quick)
    result = evaluate_scenes(predictor, loaded, config, progress=progress, root=root)
    result.update(
        protocol=args.protocol,
        dataset=args.dataset,
        split=args.split,
        data_dir=None if root is None else str(root),
        files_evaluated=[str(p) for p in files[args.split]],
        # what the numbers depend on beyond the data: the weights, the samples' seed, the code
        predictor_sha256=loaded_sha256(predictor),
        seed=args.seed,
        code=code_with_plugins(),
    )
    trained = None if entry is None else entry.protocol
    result["trained_protocol"] = trained  # None: no zoo entry (constant velocity, the oracle)
    if root is None:
        print(f"files given with --test ({len(files['test'])})")
    else:
        print(f"protocol {args.protocol}, split {args.split}, data {root}")
    if trained is not None and root is not None and trained != args.protocol:
        # both protocols score the same test file: the option picks the files, not how the model was trained
        print_note(
            f"note: {args.predictor} was trained under protocol {trained!r}; --protocol {args.protocol} "
            f"chooses the files scored, so these are not {args.protocol!r} results for this model"
        )
    for note in filter(None, seen_notes(args.predictor, entry, files[args.split])):
        print_note(note)
    print(format_table(result))
    if args.top_k is not None and result["top_k"] is None:
        print_note(f"note: {args.predictor} has no sample(); --top-k ignored")
    if args.json is not None:
        # strict JSON, as every record's (a non-finite figure null, never a bare NaN a strict reader refuses)
        write_output(args.json, json.dumps(plain(result), indent=2, allow_nan=False) + "\n", "--json")
        if not is_stdout(args.json):
            print(f"wrote {shown(args.json)}")
    return 0


def _choose_files(args: argparse.Namespace) -> None:
    """Fills in the defaults of --protocol, --dataset and --split, or with --test the record of explicit
    files (protocol "custom", as `train --train/--val` records it); PipelineError when an option that
    chooses prepared files is typed with --test: it would be ignored without a word."""
    choosing = (("--data-dir", args.data_dir), ("--protocol", args.protocol), ("--dataset", args.dataset))
    if args.test is None:
        args.protocol = args.protocol or DEFAULT_PROTOCOL
        args.dataset = args.dataset or DEFAULT_DATASET
        args.split = args.split or "test"
        return
    given = [option for option, value in (*choosing, ("--split", args.split)) if value is not None]
    if given:
        verb = "does" if len(given) == 1 else "do"
        raise PipelineError(
            f"{' and '.join(given)} {verb} not go with --test (its files replace the prepared files those "
            "options choose); give one or the other"
        )
    check_data_files("--test", args.test)  # a file named twice was scored twice in "overall"
    args.protocol, args.dataset, args.split = "custom", None, "test"


def _scenes(
    args: argparse.Namespace, files: list[Path], config: EvalConfig, root: Path | None
) -> dict[Path, list[EvalScene]]:
    """The scenes of each file scored, by its path; PipelineError naming a file that holds none, before any
    is scored: its row read "0 scenes -" and the command passed, as if something had been evaluated (an
    empty --test file, or a prepared split its raw data was too short to give a scene)."""
    from predictors.evaluate import load_eval_scenes

    loaded = {Path(path): load_eval_scenes(path, config) for path in files}
    empty = next((path for path, scenes in loaded.items() if not scenes), None)
    if empty is None:
        return loaded
    if root is None:
        raise PipelineError(f"--test {empty}: holds no scenes; the evaluation needs at least one")
    name = empty.relative_to(root) if empty.is_relative_to(root) else empty
    raise PipelineError(
        f"the {args.split} split {name} of {root} holds no scenes; evaluate another --dataset or --split, or "
        "prepare data with more frames"
    )


def seen_notes(predictor: str, entry: ZooEntry | None, paths: list[Path]) -> list[str]:
    """A note for each file scored that the model saw in training (its entry's training or validation files,
    by sha256): `evaluate --test` on one's own training file printed its ADE as any other, where `train` notes
    a --test file equal to its --train."""
    notes = []
    for path, split, name in [] if entry is None else entry.seen_in_training(paths):
        role = "trained" if split == "train" else "validated (its best epoch chosen)"
        notes.append(
            f"note: {path} holds the data {predictor} was {role} on ({split} file {name}): these scores "
            "are not on held-out data"
        )
    return notes
