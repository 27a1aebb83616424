"""``crowdmpc zoo``: list, show, verify, add and remove trained predictors of the shipped and user zoos."""

from __future__ import annotations

import argparse
import json
import shlex
from pathlib import Path
from typing import Any

from pipelines.commands import examples, path_arg
from pipelines.commands.zoo_list import quick_check_line, run_list
from pipelines.errors import PipelineError, print_note

EPILOG = """examples:
  crowdmpc zoo list
  crowdmpc zoo show social_lstm_eth
  crowdmpc zoo verify
  crowdmpc zoo calibrations --predictor social_lstm_eth
  crowdmpc zoo add runs/train/social_lstm_eth/social_lstm_eth.pt --name my_social_lstm
  crowdmpc zoo add runs/train/social_lstm_eth_v2/social_lstm_eth_v2.pt --name my_social_lstm --replace
  crowdmpc --plugin my_predictor:MyNet zoo add runs/train/my_net_eth/my_net_eth.pt
  crowdmpc zoo remove my_social_lstm

Two zoos, each NAME.pt (state_dict) + NAME.json (config) per model and a manifest.json with their sha256,
training data and metrics: the shipped zoo, checkpoints/ (or $CROWDMPC_CHECKPOINTS), read-only; and the user
zoo, $CROWDMPC_ZOO (default $XDG_DATA_HOME/crowdmpc/zoo, else ~/.local/share/crowdmpc/zoo, or --dir), where
`add` writes and `remove` deletes. A user model may not take a shipped model's name nor a built-in predictor's
(an entry that has one, written by hand or added before the shipped zoo took the name, never loads: `list`
marks it !, `verify` fails). `add` under a name the zoo has already is refused (adding the very same model
again changes nothing) unless --replace says to replace that entry; so is a name whose files would be the
zoo's own (manifest, calibrations), or files there that are no entry's of that name (your own NAME.pt: move it
away first). Parallel adds and removes take turns. The metrics file must be the one `crowdmpc train` wrote for
these weights. A file whose sha256 differs from its manifest is refused when loaded; `verify` checks every
entry of both zoos and names the hidden files an add or remove stopped on the way left in the user zoo
(`remove --leftovers NAME` removes them, keeping the entry; `remove NAME` removes them with it). A model of a
plugin's kind loads once the plugin is registered (crowdmpc --plugin module:NetClass zoo ...); the shipped zoo
holds only the kinds the project ships.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "zoo",
        help="the model zoos of trained predictors (shipped, and your own)",
        description="List, show, verify, add and remove trained predictors of the model zoos; list their "
        "calibrations.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--dir",
        type=path_arg,
        default=None,
        help="the user zoo directory (default $CROWDMPC_ZOO, see below); list, show, verify and calibrations "
        "refuse one that does not exist (more likely a typo than an empty zoo), add makes it",
    )
    actions = parser.add_subparsers(dest="zoo_command", metavar="ACTION", required=True)
    actions.add_parser(
        "list",
        help="one line per model of both zoos: the predictor class it loads as, its model kind and metrics",
        **examples("crowdmpc zoo list", "crowdmpc zoo --dir my_zoo list"),
    )
    show = actions.add_parser(
        "show", help="the manifest entry of one model", **examples("crowdmpc zoo show social_lstm_eth")
    )
    show.add_argument("name", help="the model's zoo name (zoo list's first column)")
    actions.add_parser(
        "verify",
        help="check every entry's files against its manifest (exit 1 on a problem)",
        **examples("crowdmpc zoo verify"),
    )
    calibrations = actions.add_parser(
        "calibrations",
        help="one line per conformal calibration block in force (crowdmpc calibrate), of both zoos",
        **examples(
            "crowdmpc zoo calibrations",
            "crowdmpc zoo calibrations --predictor social_lstm_eth --plot runs/margins.png",
        ),
    )
    calibrations.add_argument("--predictor", default=None, help="only this predictor's blocks")
    calibrations.add_argument(
        "--plot",
        type=path_arg,
        default=None,
        metavar="FILE.png",
        help="also draw the predictor's margins against the horizon step (needs --predictor)",
    )
    _add_and_remove(actions)
    parser.set_defaults(func=run)


def _add_and_remove(actions: Any) -> None:
    """The actions that change a zoo: ``add`` and ``remove``."""
    add = actions.add_parser(
        "add",
        help="copy a trained checkpoint pair into the user zoo",
        **examples(
            "crowdmpc zoo add runs/train/social_lstm_eth/social_lstm_eth.pt --name my_social_lstm",
            "crowdmpc zoo add runs/train/v2/social_lstm_eth.pt --name my_social_lstm --replace",
        ),
    )
    add.add_argument("weights", type=path_arg, help="NAME.pt written by `crowdmpc train` (beside NAME.json)")
    add.add_argument("--name", default=None, help="zoo name (default: the checkpoint's own name)")
    add.add_argument(
        "--protocol",
        default=None,
        help="protocol label (default: the training run's: paper, loo or custom); paper and loo only for "
        "a run of that protocol, any other label for a run of one's own files",
    )
    add.add_argument(
        "--metrics",
        type=path_arg,
        default=None,
        help="metrics JSON of these weights (default NAME.metrics.json beside the weights)",
    )
    add.add_argument(
        "--replace",
        action="store_true",
        help="replace the zoo's entry of the same name (without it, adding a taken name is an error)",
    )
    add.add_argument(
        "--shipped",
        action="store_true",
        help="maintainers: add to the shipped zoo (checkpoints/, tracked in git) instead of the user zoo",
    )
    remove = actions.add_parser(
        "remove",
        help="remove a model and its files from the user zoo (a training run's folder given as --dir loses "
        "the NAME.pt and NAME.json that were added from it)",
        **examples("crowdmpc zoo remove my_social_lstm"),
    )
    remove.add_argument(
        "name", help="the user zoo's entry to remove, with its files (with --leftovers: only its leftovers)"
    )
    remove.add_argument(
        "--leftovers",
        action="store_true",
        help="remove only the hidden files an add or remove of NAME stopped on the way left (`verify` names "
        "them); its entry, if it has one, stays",
    )
    remove.add_argument(
        "--calibrations",
        action="store_true",
        help="remove only NAME's calibration blocks from the user zoo's calibrations.json, which a plain "
        "remove keeps (a re-add of the same weights uses them again); its entry, if it has one, stays",
    )


def run(args: argparse.Namespace) -> int:
    from predictors import registry, zoo, zoo_remove
    from predictors.errors import PredictorError

    if args.zoo_command in ("list", "show", "verify", "calibrations"):
        zoo.readable_zoo_dir(args.dir)
    if args.zoo_command == "list":
        return run_list(args.dir)
    if args.zoo_command == "show":
        located = zoo.locate(args.name, args.dir)
        if located is None and args.name in registry.PREDICTORS:
            raise PipelineError(f"{args.name!r} is a built-in predictor, with no weights: no zoo holds it")
        if located is None:
            from predictors.errors import UnknownPredictor

            raise UnknownPredictor(args.name, sorted({e.entry.name for e in zoo.zoo_entries(args.dir)}))
        print(json.dumps({**located.entry.to_json(), "zoo": located.source}, indent=2))
        never = registry.never_loads(located)  # a user entry named as a built-in predictor
        if never is not None:
            print_note(f"note: {never}")
        return 0
    if args.zoo_command == "verify":
        results = zoo.verify_entries(args.dir)
        results = [(located, registry.never_loads(located) or problem) for located, problem in results]
        for located, problem in results:
            label = located.entry.name if located.source == zoo.SHIPPED else f"{located.entry.name} (user)"
            print(f"{label}: {'ok' if problem is None else problem}")
        bad = sum(problem is not None for _, problem in results)
        print(f"{len(results) - bad} of {len(results)} entries ok")
        _report_leftovers(zoo.user_zoo_dir(args.dir), args.dir)
        return 1 if bad else 0
    if args.zoo_command == "calibrations":
        from pipelines.commands.calibrate_store import take_back_killed
        from pipelines.commands.zoo_calibrations import run_calibrations

        if args.dir is None:  # the blocks runs plan with: not those of a calibrate killed mid-run
            take_back_killed()

        return run_calibrations(args.dir, args.predictor, args.plot)
    if args.zoo_command == "add":
        return _add(args)
    if args.zoo_command == "remove" and args.calibrations:
        return _remove_calibrations(args)
    if args.zoo_command == "remove" and args.leftovers:
        leftovers, root = zoo_remove.remove_leftovers(args.name, args.dir)
        names = ", ".join(path.name for path in leftovers) or "none"
        print(f"removed the leftover files of {args.name} from the user zoo {root}: {names}")
        return 0
    if args.zoo_command == "remove":
        try:
            entry, root = zoo_remove.remove_from_zoo(args.name, args.dir)
        except PredictorError:
            # no entry: an add or remove stopped on the way may have left its hidden temporaries
            leftovers, root = zoo_remove.remove_leftovers(args.name, args.dir)
            if not leftovers:
                raise
            names = ", ".join(path.name for path in leftovers)
            print(f"{args.name} has no entry in the user zoo {root}; removed its leftover files {names}")
            return 0
        print(f"removed {entry.name} from the user zoo {root}")
        _kept_calibrations(entry.name, args.dir)
        return 0
    raise PipelineError(f"unknown zoo action {args.zoo_command!r}")


def _remove_calibrations(args: argparse.Namespace) -> int:
    from predictors import zoo_remove

    if args.leftovers:
        raise PipelineError("--calibrations and --leftovers are two removes: give one at a time")
    count, path = zoo_remove.remove_calibrations(args.name, args.dir)
    if not count:
        raise PipelineError(f"{path} holds no calibration block of {args.name!r}; nothing removed")
    print(f"removed the {count} calibration block(s) of {args.name} from {path}")
    return 0


def _kept_calibrations(name: str, directory: Path | None) -> None:
    """Say that the removed entry's calibration blocks stay (listed as "no model"), why, and how they go."""
    from predictors import zoo_remove

    count, path = zoo_remove.calibrations_of(name, directory)
    if count:
        option = "" if directory is None else f" --dir {shlex.quote(str(directory))}"
        print(
            f"its {count} calibration block(s) stay in {path} (`zoo calibrations`: weights 'no model'): "
            f"a zoo add of the same weights plans with them again, and sweeps planned with them resume; "
            f"`crowdmpc zoo{option} remove --calibrations {shlex.quote(name)}` removes them"
        )


def _report_leftovers(root: Path, directory: Path | None) -> None:
    """Name the hidden files an add or remove stopped on the way left in the user zoo ``root``: no entry
    names them, so no line above does, and each may be as large as a model."""
    from predictors import zoo, zoo_edit

    if zoo.is_shipped(root) or not root.is_dir():
        return
    option = "" if directory is None else f" --dir {shlex.quote(str(directory))}"
    for name, path in zoo_edit.leftover_files(root):
        print(
            f"{path}: left by an add or remove of {name} that stopped on the way (or is running now); "
            f"`crowdmpc zoo{option} remove --leftovers {shlex.quote(name)}` removes it"
        )


def _add(args: argparse.Namespace) -> int:
    from predictors import checkpoint, zoo, zoo_edit
    from predictors.errors import PredictorError

    if args.shipped and args.dir is not None:
        raise PipelineError("--shipped adds to the shipped zoo; it does not go with --dir")
    if args.shipped and not (zoo.checkpoints_dir().parent / "pyproject.toml").is_file():
        # An installed crowdmpc's zoo is package data inside site-packages: maintainers add to a clone's.
        raise PipelineError(
            f"--shipped adds to a clone's checkpoints/, and {zoo.checkpoints_dir()} is not one (an installed "
            "package); add to your user zoo without --shipped"
        )
    # before anything is read: the user zoo, never the shipped one unless a maintainer says --shipped
    root = zoo.checkpoints_dir() if args.shipped else zoo.writable_zoo_dir(args.dir)
    if not args.weights.is_file():
        raise PipelineError(
            f"{args.weights} is not a file; give the weights `crowdmpc train` wrote (NAME.pt)"
        )
    if args.weights.suffix == ".ckpt":  # it asked for a last.metrics.json, which no run writes
        raise PipelineError(
            f"{args.weights} is a Lightning training checkpoint, not a zoo one; add the NAME.pt `crowdmpc "
            "train` wrote in the run's folder (its best epoch's weights)"
        )
    metrics_path = args.metrics or args.weights.with_suffix(".metrics.json")
    if not metrics_path.is_file():  # a folder or /dev/zero exists, and is no metrics file either
        why = "is not a file" if metrics_path.exists() else "does not exist"
        raise PipelineError(f"{metrics_path} {why}; pass --metrics FILE (written by `crowdmpc train`)")
    if metrics_path.stat().st_size > checkpoint.MAX_DOCUMENT_BYTES:
        raise PipelineError(
            f"{metrics_path}: more than the {checkpoint.MAX_DOCUMENT_BYTES} bytes a metrics file may have"
        )
    from predictors.errors import DuplicateKey, unique_keys

    try:  # a key given twice is refused, as in every JSON file a user edits
        summary = json.loads(metrics_path.read_text(encoding="utf-8"), object_pairs_hook=unique_keys)
    except DuplicateKey as exc:
        raise PipelineError(f"{metrics_path}: {exc}") from None
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, not UTF-8, nested too deeply
        raise PipelineError(f"{metrics_path}: not valid JSON ({exc})") from None
    if not isinstance(summary, dict):
        raise PipelineError(f"{metrics_path}: expected the JSON object `crowdmpc train` writes")
    for key in ("training", "training_data", "metrics"):
        if not isinstance(summary.get(key, {}), dict):
            raise PipelineError(f'{metrics_path}: "{key}" must be a JSON object')
    from pipelines.commands import zoo_metrics

    # the zoo name is the user's or the checkpoint's: a metrics file may be shared by mistake
    name = args.name if args.name is not None else args.weights.stem
    zoo_metrics.check_metrics_types(summary, metrics_path)
    zoo_metrics.check_protocol_label(args.protocol, summary, metrics_path)
    # add_to_zoo checks the name before it writes anything
    training = dict(summary.get("training", {}))
    training_data = dict(summary.get("training_data", {}))
    if args.protocol:
        training_data["protocol"] = args.protocol
    training |= {"code": summary["code"]} if isinstance(summary.get("code"), dict) else {}  # that trained it

    def check_pair(checked) -> dict:
        # the metrics and the size are of the bytes the zoo keeps: read apart, a pair replaced meanwhile
        # had its metrics checked against, and its size taken of, other files than were added
        zoo_metrics.check_metrics_describe(args.weights, metrics_path, summary, checked)
        return {"size_kb": round(len(checked.weights) / 1024, 1)}

    try:
        entry, previous = zoo_edit.add_entry(
            args.weights,
            name=name,
            protocol=args.protocol or summary.get("protocol", "custom"),
            training_data=training_data,
            metrics=summary.get("metrics", {}),
            training=training,
            directory=None if args.shipped else root,
            shipped=args.shipped,
            replace=args.replace,
            check_pair=check_pair,
        )
    except PredictorError as exc:
        raise zoo_metrics.unloadable_weights(args.weights, metrics_path, summary) or exc from None
    print(_added_line(entry, previous, args, root))
    # quoted as simulate, evaluate and export name the model in the same note
    note = quick_check_line(repr(entry.name), entry.training)
    if note is not None:  # docs/extending.md: such a model is never mistaken for a trained one
        print_note(note)
    return 0


def _added_line(entry, previous, args: argparse.Namespace, root: Path) -> str:
    """What ``zoo add`` did, in one line: added, replaced (and what was there), or nothing."""
    which = "shipped" if args.shipped else "user"
    sha = f"sha256 {entry.sha256[:12]}…"
    if previous is None:
        return f"added {entry.name} ({entry.file}, {sha}) to the {which} zoo {root}"
    if previous is entry:  # add_entry returns the one object when it wrote nothing (--replace or not)
        return (
            f"{entry.name} is already in the {which} zoo {root} with these weights ({sha}); nothing changed"
        )
    if previous == entry:
        return f"{entry.name}: the {which} zoo's copy in {root} was damaged; wrote it again ({sha})"
    return (
        f"replaced {entry.name} (was sha256 {previous.sha256[:12]}…, model {previous.model}) with "
        f"{entry.file} ({sha}, model {entry.model}) in the {which} zoo {root}"
    )
