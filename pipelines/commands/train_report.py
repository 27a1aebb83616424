"""What ``crowdmpc train`` records and prints once a run has trained: the training data's identity, the
TrajNet++ metrics of the best epoch, the epoch times, the closing lines."""

from __future__ import annotations

import argparse
import itertools
import os
import shlex
from pathlib import Path
from typing import Any


def data_record(files: dict[str, list[Path]], root: Path | None, protocol: str) -> dict:
    """Training data identity for the zoo: each file's sha256 and one hash over train + val."""
    import hashlib

    from predictors.hashing import sha256_file

    record: dict[str, Any] = {"protocol": protocol, "files": {}}
    digest = hashlib.sha256()
    for split in ("train", "val", "test"):
        paths = files[split]
        record["files"][split] = {
            name: sha256_file(p) for name, p in zip(file_labels(paths, root), paths, strict=True)
        }
        if split != "test":
            for name, sha in sorted(record["files"][split].items()):
                digest.update(f"{split}/{name}:{sha}\n".encode())
    record["sha256"] = digest.hexdigest()
    return record


def file_labels(paths: list[Path], root: Path | None) -> list[str]:
    """Each file's name in the record: relative to ``root`` (the prepared data of a protocol) when it lies
    there; the others by their bare names, or, when two share one (d1/t.ndjson, d2/t.ndjson: by name alone,
    one replaced the other in the record and in its hash), relative to their common directory. A protocol's
    files outside its prepared data (loo's TrajNet++ files) keep their bare names, so the record does not
    depend on where they sit."""
    under = [root is not None and p.is_relative_to(root) for p in paths]
    outside = [p for p, inside in zip(paths, under, strict=True) if not inside]
    names = [p.name for p in outside]
    if len(set(names)) < len(names):
        # lexically absolute, not resolved: a symlinked file keeps the name it was given
        absolute = [Path(os.path.abspath(p)) for p in outside]
        common = Path(os.path.commonpath([p.parent for p in absolute]))
        names = [str(p.relative_to(common)) for p in absolute]
    named = iter(names)
    return [
        str(p.relative_to(root)) if inside and root else next(named)
        for p, inside in zip(paths, under, strict=True)
    ]


def finished_outputs(out: Path) -> list[str]:
    """The weights and metrics a finished run wrote into ``out`` (NAME.pt, NAME.metrics.json), by name."""
    if not out.is_dir():
        return []
    names = [p.name for p in out.iterdir() if p.is_file() and not p.name.startswith(".")]
    return sorted(n for n in names if n.endswith((".pt", ".metrics.json")))


def evaluate_splits(
    args: argparse.Namespace,
    predictor: Any,
    files: dict[str, Any],
    root: Any,
    top_k: int | None,
    evaluated: dict[Path, list[Any]] | None = None,
) -> dict[str, dict[str, Any]]:
    """ADE/FDE of the trained model on the validation and test files it was given; ``evaluated``: their
    scenes by path, as ``load_eval_scenes`` read them (a file not in it is read here)."""
    from predictors.evaluate import EvalConfig, evaluate_scenes, load_eval_scenes

    evaluated = evaluated or {}
    metrics = {}
    for split in ("val", "test"):
        if files[split]:
            result = evaluate_scenes(
                predictor,
                {Path(p): evaluated[p] if p in evaluated else load_eval_scenes(p) for p in files[split]},
                # evaluate's own sampling seed, not the training --seed: the top-k stored (and shown by `zoo
                # list`) is then what `crowdmpc evaluate --top-k K` prints, and nets trained with different
                # seeds are scored on the same noise
                EvalConfig(top_k=top_k),
                progress=False if args.no_progress else None,
                root=root,
            )
            if result["overall"].get("scenes"):  # an empty --test file has nothing to report
                metrics[split] = {k: v for k, v in result["overall"].items() if v is not None}
    return metrics


def _plugin_option(model: str) -> str:
    """``--plugin MODEL `` when ``model`` is a plugin's kind (later commands must register it too)."""
    from predictors.models import model_kind

    return f"--plugin {shlex.quote(model)} " if model_kind(model).source == "plugin" else ""


def print_summary(summary: dict[str, Any], best: str, weights: Path, top_k: int | None) -> None:
    limit = summary["training"].get("limit_batches")
    # its val_ade is over the batches validated each epoch, the val line below over every scene
    over = "" if limit is None else f" (val_ade over {limit} validation batch{'es' * (limit != 1)})"
    print(f"{summary['name']}: best checkpoint {best}{over}; weights {weights} (+ .json)")
    training = summary["training"]
    if "stopped_early_after" in training:
        patience = training["patience"]
        print(
            f"  stopped early after {training['stopped_early_after']} of {training['epochs']} epochs: "
            f"validation ADE had not improved in the last {patience} (--patience {patience})"
        )
    for split, m in summary["metrics"].items():
        line = f"  {split}: ADE {m['ade']:.3f} m  FDE {m['fde']:.3f} m  ({m['scenes']} scenes)"
        if "topk_ade" in m:
            line += f"  top-{top_k} ADE {m['topk_ade']:.3f}  FDE {m['topk_fde']:.3f}"
        print(line)
    add = f"crowdmpc {_plugin_option(summary['model'])}zoo add {shlex.quote(str(weights))}"
    name_option, held = _name_option(weights.stem)
    # a retrained model's name is often its zoo entry's already: say how to replace that entry, on purpose
    replace = f" (your zoo holds {held} already: `{add} --replace` replaces that entry)" if held else ""
    print(
        f"  median epoch time {summary['training']['median_epoch_time_s']} s; add to the zoo with "
        f"`{add}{name_option}`{replace}"
    )


def _name_option(name: str) -> tuple[str, str | None]:
    """`` --name FREE`` when ``zoo add`` would refuse the checkpoint's own name ``NAME``, else nothing; and
    the user zoo's entry of that name (in any case), else None. A shipped or built-in name (the default
    ``--out`` names a model as the shipped one of its kind and protocol: social_lstm_eth) suggests
    ``my_NAME``, the rule being ``zoo_edit.user_name_refusal``'s; a name the user zoo holds (a model trained
    again, or resumed, under its entry's name) ``NAME_2``, where the bare command was refused. The name
    suggested is none the user zoo has either (a second run's hint named the first's, which ``zoo add`` then
    refused). A manifest that does not read leaves the hint as it is (``zoo add`` says what is wrong)."""
    from predictors.errors import PredictorError
    from predictors.zoo import user_zoo_dir, zoo_names
    from predictors.zoo_edit import user_name_refusal

    try:
        held = {entry.lower(): entry for entry in zoo_names(user_zoo_dir())}
        taken = user_name_refusal(name) is not None
        if not taken and name.lower() not in held:
            return "", None
        stem = f"my_{name}" if taken else name
        free = next(
            candidate
            for candidate in itertools.chain(
                [stem] if taken else [], (f"{stem}_{i}" for i in itertools.count(2))
            )
            if user_name_refusal(candidate) is None and candidate.lower() not in held
        )
    except PredictorError:
        return "", None
    return f" --name {free}", None if taken else held[name.lower()]


def epoch_times_from_csv(log_dir: str | Path) -> list[float]:
    """Training epoch wall times logged by the module (``epoch_time_s``)."""
    import csv

    path = Path(log_dir) / "metrics.csv"
    if not path.is_file():
        return []
    with open(path, encoding="utf-8") as f:
        return [float(row["epoch_time_s"]) for row in csv.DictReader(f) if row.get("epoch_time_s")]


def median_epoch_time(times: list[float]) -> float | None:
    """The median of the epochs' times in s, to 0.01 s (None without any): of an even count, the mean of the
    middle two (``sorted(times)[len // 2]``, the upper one, gave 0.05 s for epochs of 0.047 and 0.033 s)."""
    import statistics

    return round(statistics.median(times), 2) if times else None
