"""``crowdmpc zoo list``: one line per model of both zoos, with what marks a model not to be taken for a
trained one (``*``: a quick check) or one that never loads (``!``)."""

from __future__ import annotations

from pathlib import Path
from typing import Final

# The widest a cell of a manifest's own text is shown (a plugin's "module:NetClass" kind fits): a hand-edited
# kind, class or protocol of 100,000 characters made every line of the table as wide.
CELL_LIMIT: Final[int] = 60


def run_list(directory: Path | None) -> int:
    from predictors import registry, zoo

    entries = zoo.zoo_entries(directory)
    if not entries:
        roots = " and ".join(f"the {source} zoo {root}" for source, root in zoo.zoo_roots(directory))
        print(f"no models in {roots}")
        return 0
    # a user entry whose name a built-in predictor or a shipped model takes: listed, it read as usable
    never = [registry.never_loads(located) for located in entries]
    print(format_list(entries, [line is not None for line in never]))
    print("ADE/FDE in metres, TrajNet++ metrics of the primary pedestrian (9 -> 12 steps)")
    if any(quick_check(located.entry.training) is not None for located in entries):
        print("* a quick check (train --limit-batches: a few batches an epoch), not a trained model")
    for line in never:
        if line is not None:
            print(f"! {line}")
    return 0


def _metric(metrics: dict, split: str, key: str) -> str:
    """A metric as a table cell: "-" when absent, "?" when the manifest holds something else than a number."""
    values = metrics.get(split, {})
    value = values.get(key) if isinstance(values, dict) else None
    if value is None:
        return "-"
    return "?" if isinstance(value, bool) or not isinstance(value, int | float) else f"{value:.3f}"


def _pooling(located) -> str:
    """The net's pooling as a table cell: "-" for a kind without one, "?" for a config that does not read."""
    from predictors import checkpoint
    from predictors.errors import PredictorError

    try:
        _, config = located.entry.paths(located.root, located.manifest)
        net = checkpoint.read_document(config, checkpoint.CONFIG_FORMAT, "crowdmpc predictor config").get(
            "net"
        )
    except (OSError, PredictorError):
        return "?"
    if not isinstance(net, dict):
        return "?"
    pooling = net.get("pooling", "-")
    return pooling if isinstance(pooling, str) and len(pooling) <= 16 else "?"


def _cell(value: object) -> str:
    """A manifest's value as a table cell, cut to ``CELL_LIMIT`` characters as messages cut a file's values
    (``short_repr``); one holding a line break or another unprintable character is shown escaped, so that it
    cannot break its row in two."""
    from predictors.errors import short_repr

    text = str(value)
    if not text.isprintable():
        return short_repr(text, CELL_LIMIT)
    return text if len(text) <= CELL_LIMIT else f"{text[: CELL_LIMIT - 3]}..."


def _loaded_class(entry) -> str:
    """The class the entry loads as, told by its model kind: the shipped manifest's "class" was written
    before model kinds (``SocialLSTMPredictor`` for the LSTMs, which load as ``LearnedPredictor``), so one
    kind showed two classes. An unregistered plugin kind shows the class ``zoo add`` recorded."""
    from predictors.errors import PredictorError
    from predictors.models import model_kind

    try:
        return model_kind(entry.model).predictor_class_name
    except PredictorError:
        return entry.cls


def format_list(located_entries, never_loads: list[bool] | None = None) -> str:
    """The table of ``located_entries``; ``never_loads``, per entry, marks with ``!`` one that never loads."""
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
        "zoo",
    ]
    rows = []
    for index, located in enumerate(located_entries):
        entry = located.entry
        marks = " *" if quick_check(entry.training) is not None else ""
        marks += " !" if never_loads is not None and never_loads[index] else ""
        m = entry.metrics
        topk = "-"
        if _metric(m, "test", "topk_ade") != "-":
            topk = f"{_metric(m, 'test', 'topk_ade')}/{_metric(m, 'test', 'topk_fde')}"
        rows.append(
            [
                entry.name + marks,
                _cell(_loaded_class(entry)),
                _cell(entry.model),
                _pooling(located),
                _cell(entry.protocol),
                _metric(m, "val", "ade"),
                _metric(m, "val", "fde"),
                _metric(m, "test", "ade"),
                _metric(m, "test", "fde"),
                topk,
                _cell(entry.training.get("size_kb", "-")),
                located.source,
            ]
        )
    from predictors.text_table import aligned_lines

    rows = [[str(c) for c in r] for r in rows]
    return "\n".join(aligned_lines(header, rows, numbers_right=False))


def quick_check(training: dict) -> int | None:
    """The batches an epoch an entry trained on when ``train --limit-batches`` cut its epochs, else None."""
    limit = training.get("limit_batches")
    return limit if isinstance(limit, int) and not isinstance(limit, bool) else None


def quick_check_line(shown: str, training: dict) -> str | None:
    """The note on an entry (named ``shown``) that ``quick_check`` finds, else None."""
    limit = quick_check(training)
    if limit is None:
        return None
    batches = f"{limit} batch{'es' * (limit != 1)} an epoch (train --limit-batches {limit})"
    return f"note: {shown} trained on {batches}: a quick check, not a trained model (zoo list: *)"
