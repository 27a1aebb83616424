"""``crowdmpc data``: prepare TrajNet++ scenes from raw BIWI EWAP, dataset statistics, synthetic ORCA data."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Final

from crowdsim.profiles import PROFILES
from crowdsim.scenarios import MAX_HUMANS
from pipelines.commands import PREPARE_ROOM, check_writable, path_arg
from pipelines.commands.data_synth import run_synth
from pipelines.commands.evaluate import counted, seed_arg
from pipelines.commands.output_paths import file_output_arg, output_arg
from pipelines.errors import PipelineError, print_note, writes_named

# A synthetic episode takes ~30 ms and ~15 kB of scenes (7 humans): 100 000 (as `simulate --episodes`) is most
# of an hour and 1.5 GB, far more than any training set here; 10^9 ran silently for days.
MAX_SYNTH_EPISODES: Final[int] = 100_000

EPILOG = """examples:
  crowdmpc data prepare --raw ../shared/data/raw_ewap --out data/prepared
  crowdmpc data stats data/prepared
  crowdmpc data synth --out data/synth/orca_circle.ndjson --episodes 100 --humans 7 --seed 0 --scenario circle
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "data",
        help="prepare, inspect and synthesise TrajNet++ datasets",
        description="Prepare TrajNet++ ndjson scenes from raw BIWI EWAP annotations, print dataset "
        "statistics, or synthesise scenes from ORCA crowds.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = parser.add_subparsers(dest="data_command", metavar="ACTION", required=True)
    _register_prepare(actions)
    _register_stats(actions)
    _register_synth(actions)


def _register_prepare(actions) -> None:
    prepare = actions.add_parser(
        "prepare",
        help="raw EWAP obsmat.txt -> TrajNet++ train/val/test ndjson",
        description="Convert raw_ewap/seq_eth and seq_hotel to TrajNet++ scenes (21 steps, a start every 2 "
        "steps) with a temporal 70/10/20 split per sequence, and check the hotel conversion against the "
        "official TrajNet++ file when it lies beside the raw data.",
        epilog="example:\n  crowdmpc data prepare --raw ../shared/data/raw_ewap --out data/prepared\n",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    prepare.add_argument(
        "--raw", required=True, type=path_arg, help="raw_ewap directory (or the directory holding it)"
    )
    prepare.add_argument(
        "--out",
        required=True,
        type=output_arg,
        help="output directory for {train,val,test}/*.ndjson; a second prepare into it waits for the first "
        "(a hidden .NAME.prepare.lock beside it)",
    )
    prepare.add_argument(
        "--no-check", action="store_true", help="skip the comparison with reference conversions"
    )
    prepare.add_argument(
        "--keep-all", action="store_true", help="keep every scene (TrajNet++ keeps only 10%% of static ones)"
    )
    prepare.add_argument(
        "--no-tags",
        action="store_true",
        help="skip the TrajNet++ categorisation (a Kalman fit per scene): faster, untagged, nothing dropped",
    )
    prepare.add_argument(
        "--seed",
        type=seed_arg,
        default=None,  # None: not typed, so --no-tags can refuse only a seed the user gave
        help="seed of the TrajNet++ categorisation: the draws of its Kalman fits, which may change a scene's "
        "type, and of the static-scene acceptance (default 42; not with --no-tags, which draws nothing)",
    )
    prepare.add_argument(
        "--no-progress", action="store_true", help="no progress bar (drawn on a terminal only)"
    )
    prepare.set_defaults(func=run_prepare)


def _register_stats(actions) -> None:
    stats = actions.add_parser(
        "stats",
        help="scenes, tracks, pedestrians and agents per scene of an ndjson file or every one in a directory",
        description="Print a table of scenes, tracks, pedestrians, agents per scene (min/mean/max), scene "
        "types and frame rates, one row per file.",
        epilog="example:\n  crowdmpc data stats data/prepared\n",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    stats.add_argument("directory", type=path_arg, help="an ndjson file, or a folder searched for them")
    stats.set_defaults(func=run_stats)


def _register_synth(actions) -> None:
    synth = actions.add_parser(
        "synth",
        help="simulate ORCA crowds and write them as TrajNet++ scenes",
        description="Run seeded ORCA crowd episodes (CrowdNav-like scenarios) and write TrajNet++ ndjson "
        "scenes (2.5 Hz, 21-step scenes), e.g. to train a predictor on the pedestrians it meets in closed "
        "loop.",
        epilog="example:\n  crowdmpc data synth --out data/synth/orca.ndjson --episodes 100 --humans 7 "
        "--seed 0\n",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    synth.add_argument(
        "--out",
        required=True,
        type=file_output_arg,
        help="ndjson file to write; a second synth into it while one runs is refused (a hidden "
        ".NAME.synth.lock beside it)",
    )
    synth.add_argument(
        "--episodes",
        required=True,
        type=counted(1, MAX_SYNTH_EPISODES),
        help=f"episodes to simulate (1..{MAX_SYNTH_EPISODES})",
    )
    synth.add_argument(
        "--humans", required=True, type=counted(1, MAX_HUMANS), help=f"humans per episode (1..{MAX_HUMANS})"
    )
    synth.add_argument(
        "--seed", required=True, type=seed_arg, help="first episode's seed (episode i uses seed + i)"
    )
    synth.add_argument(
        "--scenario",
        choices=("circle", "perpendicular"),
        default="circle",
        help="where the humans start and head: circle (crossing a circle) or perpendicular (crossing at a "
        "right angle) (default circle)",
    )
    synth.add_argument("--no-progress", action="store_true", help="no progress bar of the episodes")
    synth.add_argument(
        "--with-robots",
        action="store_true",
        help="include three robots in the crowd, ORCA agents that avoid the humans on their way to their "
        "goals (never primaries)",
    )
    synth.add_argument(
        "--profile",
        choices=sorted(PROFILES),
        default="paper",
        help="simulation conventions (default paper; v1, the first simulator's, made the shipped "
        "social_lstm_synth's data)",
    )
    synth.add_argument("--replace", action="store_true", help="replace an existing --out file")
    synth.set_defaults(func=run_synth)


def run_prepare(args: argparse.Namespace) -> int:
    from predictors.data.locate import raw_ewap_dir, raw_ewap_problem
    from predictors.data.prepare import prepare_ewap
    from predictors.data.selfcheck import default_references, expected_references
    from predictors.data.trajnet_scenes import TRAJNETPP_ACCEPTANCE

    seed = _prepare_seed(args)
    check_writable(args.out, "--out", directory=True, room=PREPARE_ROOM)
    raw = raw_ewap_dir(args.raw) if args.raw.is_dir() else None
    problem = raw_ewap_problem(args.raw) if raw is None and args.raw.is_dir() else None
    if problem is not None:
        raise PipelineError(f"--raw {args.raw}: {problem}")
    if raw is None:
        raise PipelineError(
            f"--raw {args.raw} is a file; give the folder holding seq_eth/ and seq_hotel/"
            if args.raw.is_file()
            else f"--raw {args.raw}: expected a BIWI EWAP directory holding seq_eth/obsmat.txt and "
            "seq_hotel/obsmat.txt; other data (e.g. 'frame ped x y' text) has no converter here: write it "
            "as TrajNet++ ndjson and give it to train --train/--val or evaluate --test (data/README.md, "
            "'Your own data')"
        )
    # a full disk's error names --out (a write's names no file)
    with _one_prepare_at_a_time(args.out), writes_named(args.out):
        _check_prepare_target(args.out)
        references = {} if args.no_check else default_references(raw)
        manifest = prepare_ewap(
            raw,
            args.out,
            acceptance=None if args.keep_all else TRAJNETPP_ACCEPTANCE,
            categorize_scenes=not args.no_tags,
            seed=seed,
            references=references,
            progress=False if args.no_progress else None,  # None: a bar on a terminal only
            log=lambda msg: print(msg, flush=True),
        )
    if not args.no_check:  # each check not made, said: ETH's was skipped in silence
        for name, ref in expected_references(raw).items():
            if name not in manifest["self_check"]:
                print(f"self-check skipped: no {ref.label} {ref.path.name} found at {ref.path.parent}")
    print(f"wrote {args.out / 'manifest.json'}")
    for name, check in manifest["self_check"].items():
        print(
            f"{name} check against the {check['label']} file: {check['reproduced']} / "
            f"{check['reference_scenes']} scenes reproduced exactly"
        )
    return 0


def _prepare_seed(args: argparse.Namespace) -> int:
    """The seed of the categorisation: --seed, else the default (recorded in the manifest even with
    --no-tags, as it always was). --seed with --no-tags is refused: nothing would be drawn, yet the manifest
    recorded it as if it had been."""
    from predictors.data.trajnet_scenes import DEFAULT_SEED

    if args.seed is not None and args.no_tags:
        raise PipelineError(
            f"--seed {args.seed} with --no-tags: without the categorisation nothing is drawn; "
            "drop --seed or --no-tags"
        )
    return DEFAULT_SEED if args.seed is None else args.seed


def _one_prepare_at_a_time(out: Path):
    """The lock of preparations into ``out``, a hidden ``.NAME.prepare.lock`` beside the folder (a link's
    target): two at once each moved their files in, and the last to finish won, over files of the other. A
    failed one takes away the lock and the folders it made for it (it left them, an empty raw_ewap's too)."""
    from predictors.locking import locked_undone_on_failure

    folder = out.resolve()
    return locked_undone_on_failure(
        folder.parent / f".{folder.name}.prepare.lock",
        "serialise the preparations into it",
        waiting=lambda: print(f"waiting for another `data prepare` into {out} to finish", flush=True),
    )


def _check_prepare_target(out: Path) -> None:
    """A prepared directory (its manifest) is prepared again in place; a folder holding other files is
    refused: its train/val/test files would be replaced by these (a training set was overwritten)."""
    from predictors.data.locate import load_manifest
    from predictors.data.prepare import INCOMPLETE_MARKER
    from predictors.locking import released_locks

    # a finished `data synth`'s lock stays in its folder by design, and `rm DIR/*` skips it: as good as empty
    if not out.is_dir() or not {entry.name for entry in out.iterdir()} - released_locks(out):
        return
    # a manifest of ours, whatever its files now hold: every reader says to prepare such a folder again
    if load_manifest(out) is not None:
        return
    if (out / INCOMPLETE_MARKER).is_file():  # a preparation stopped while moving its files in: finish it
        return
    raise PipelineError(
        f"--out {out} holds files but no prepared data (manifest.json of `crowdmpc data prepare`); prepare "
        "into an empty or new folder"
    )


def run_stats(args: argparse.Namespace) -> int:
    from predictors.data.stats import stats_report

    _check_prepared_files(args.directory)
    table, notes = stats_report(args.directory)
    print(table)
    for note in notes:  # each names files: one line each, whatever their names hold
        print_note(note)
    return 0


def _check_prepared_files(directory: Path) -> None:
    """A prepared folder whose files are not those its manifest lists (another preparation's beside it, or
    one stopped on the way) is refused: its statistics would describe neither."""
    from predictors.data.locate import load_manifest, prepared_mismatch
    from predictors.data.prepare import INCOMPLETE_MARKER

    manifest = load_manifest(directory) if Path(directory).is_dir() else None
    what = prepared_mismatch(directory, manifest) if manifest is not None else None
    if what is None and (Path(directory) / INCOMPLETE_MARKER).is_file():
        what = "a `data prepare` into it was stopped before it finished"
    if what is not None:
        raise PipelineError(f"{directory}: {what}; re-run `crowdmpc data prepare`")
