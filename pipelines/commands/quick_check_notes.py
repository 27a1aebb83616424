"""The note on a zoo model trained as a quick check (``train --limit-batches``), printed once a command's
inputs are accepted: printed with the notes before the load, it preceded refusals it has nothing to do with
(`simulate --predictor NAME` of a plugin's model without ``--plugin``: the note, then "is a plugin that is not
registered"). The notes that may explain a refusal (a plugin's changed module file) stay before it
(``simulate_checks.zoo_notes``)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pipelines.experiments.cells import Cell
    from predictors.manifest import ZooEntry


def quick_check_note(predictor: str | None, entry: ZooEntry | None) -> str | None:
    """The note on the zoo model ``predictor`` loads (its ``entry``) where it is a quick check, else None."""
    from pipelines.commands.zoo_list import quick_check_line

    if predictor is None or entry is None:
        return None
    return quick_check_line(repr(predictor), entry.training)


def method_quick_check_notes(cells: Iterable[Cell], entries: Mapping[str, ZooEntry]) -> list[str]:
    """``quick_check_note`` of each model a sweep's ``cells`` plan with (``entries``: the zoo entries its
    checks loaded, by name), naming the methods as ``sweep_checks.method_notes`` does."""
    methods: dict[str, list[str]] = {}  # a note's text -> its methods, in table order
    for cell in cells:
        name = cell.spec.predictor_name
        note = quick_check_note(name, entries.get(name or ""))
        if note is not None and cell.method not in methods.get(note, []):
            methods.setdefault(note, []).append(cell.method)
    return [
        note.replace("note: ", f"note: method{'s' * (len(named) > 1)} {', '.join(map(repr, named))}: ", 1)
        for note, named in methods.items()
    ]
