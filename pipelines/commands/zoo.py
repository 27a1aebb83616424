"""``crowdmpc zoo``: list, show, verify and add trained predictors (``checkpoints/manifest.json``)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from pipelines.errors import PipelineError

EPILOG = """examples:
  crowdmpc zoo list
  crowdmpc zoo show social_lstm_eth
  crowdmpc zoo verify
  crowdmpc zoo add runs/train/social_lstm_eth/social_lstm_eth.pt

The zoo lives in checkpoints/ (or $CROWDMPC_CHECKPOINTS): NAME.pt (state_dict) + NAME.json (config) per
model, and manifest.json with their sha256, training data and metrics. A file whose sha256 differs from the
manifest is refused when loaded; `verify` checks every entry.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "zoo",
        help="the model zoo of trained predictors",
        description="List, show, verify and add trained predictors of the model zoo.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--dir", type=Path, default=None, help="zoo directory (default checkpoints/)")
    actions = parser.add_subparsers(dest="zoo_command", metavar="ACTION", required=True)
    actions.add_parser("list", help="one line per model with its metrics")
    show = actions.add_parser("show", help="the manifest entry of one model")
    show.add_argument("name")
    actions.add_parser("verify", help="check every entry's files against the manifest (exit 1 on a problem)")
    add = actions.add_parser("add", help="copy a trained checkpoint pair into the zoo")
    add.add_argument("weights", type=Path, help="NAME.pt written by `crowdmpc train` (beside NAME.json)")
    add.add_argument("--name", default=None, help="zoo name (default: the checkpoint's own name)")
    add.add_argument(
        "--protocol", default=None, help="protocol label (default: the training run's: paper, loo or custom)"
    )
    add.add_argument(
        "--metrics",
        type=Path,
        default=None,
        help="metrics JSON (default NAME.metrics.json beside the weights)",
    )
    parser.set_defaults(func=run)


def _metric(metrics: dict, split: str, key: str) -> str:
    """A metric as a table cell: "-" when absent, "?" when the manifest holds something else than a number."""
    values = metrics.get(split, {})
    value = values.get(key) if isinstance(values, dict) else None
    if value is None:
        return "-"
    return "?" if isinstance(value, bool) or not isinstance(value, int | float) else f"{value:.3f}"


def format_list(entries, root: Path) -> str:
    header = [
        "name",
        "class",
        "model",
        "pooling",
        "protocol",
        "val ADE",
        "val FDE",
        "test ADE",
        "test FDE",
        "top-20 ADE/FDE",
        "kB",
    ]
    rows = []
    for entry in entries:
        m = entry.metrics
        topk = "-"
        if _metric(m, "test", "topk_ade") != "-":
            topk = f"{_metric(m, 'test', 'topk_ade')}/{_metric(m, 'test', 'topk_fde')}"
        try:
            pooling = json.loads((root / entry.config).read_text())["net"]["pooling"]
        except (OSError, KeyError, TypeError, json.JSONDecodeError):
            pooling = "?"
        rows.append(
            [
                entry.name,
                entry.cls,
                entry.model,
                pooling,
                entry.protocol,
                _metric(m, "val", "ade"),
                _metric(m, "val", "fde"),
                _metric(m, "test", "ade"),
                _metric(m, "test", "fde"),
                topk,
                entry.training.get("size_kb", "-"),
            ]
        )
    rows = [[str(c) for c in r] for r in rows]
    widths = [max(len(r[k]) for r in [header, *rows]) for k in range(len(header))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in [header, *rows]]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from predictors import zoo

    root = zoo.checkpoints_dir(args.dir)
    if args.zoo_command == "list":
        entries = list(zoo.read_manifest(root).values())
        if not entries:
            print(f"the zoo in {root} is empty")
            return 0
        print(format_list(entries, root))
        print("ADE/FDE in metres, TrajNet++ metrics of the primary pedestrian (9 -> 12 steps)")
        return 0
    if args.zoo_command == "show":
        entry = zoo.find_entry(args.name, root)
        print(json.dumps(entry.to_json(), indent=2))
        return 0
    if args.zoo_command == "verify":
        results = zoo.verify(root)
        for name, problem in results:
            print(f"{name}: {'ok' if problem is None else problem}")
        bad = sum(problem is not None for _, problem in results)
        print(f"{len(results) - bad} of {len(results)} entries ok")
        return 1 if bad else 0
    if args.zoo_command == "add":
        metrics_path = args.metrics or args.weights.with_suffix(".metrics.json")
        if not metrics_path.is_file():
            raise PipelineError(
                f"{metrics_path} does not exist; pass --metrics FILE (written by `crowdmpc train`)"
            )
        try:
            summary = json.loads(metrics_path.read_text())
        except json.JSONDecodeError as exc:
            raise PipelineError(f"{metrics_path}: not valid JSON ({exc})") from None
        if not isinstance(summary, dict):
            raise PipelineError(f"{metrics_path}: expected the JSON object `crowdmpc train` writes")
        for key in ("training", "training_data", "metrics"):
            if not isinstance(summary.get(key, {}), dict):
                raise PipelineError(f'{metrics_path}: "{key}" must be a JSON object')
        name = args.name if args.name is not None else summary.get("name") or args.weights.stem
        # add_to_zoo checks the name before it writes anything
        training = dict(summary.get("training", {}))
        training_data = dict(summary.get("training_data", {}))
        if args.protocol:
            training_data["protocol"] = args.protocol
        training["size_kb"] = round(args.weights.stat().st_size / 1024, 1)
        entry = zoo.add_to_zoo(
            args.weights,
            name=name,
            protocol=args.protocol or summary.get("protocol", "custom"),
            training_data=training_data,
            metrics=summary.get("metrics", {}),
            training=training,
            directory=root,
        )
        print(f"added {entry.name} ({entry.file}, sha256 {entry.sha256[:12]}…) to {root}")
        return 0
    raise PipelineError(f"unknown zoo action {args.zoo_command!r}")
