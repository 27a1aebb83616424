"""table.md's note on which crossings a cell's episodes are: counted from the episodes recorded, not assumed
from their number (episode i of the plan is circle for even i, perpendicular for odd)."""

from __future__ import annotations

import pytest

from pipelines.experiments.cells import get_experiment
from pipelines.experiments.summary import summarize
from pipelines.experiments.tables import markdown_table
from tests.pipelines.test_small_fixes import _records


def _note(kept: dict[str, tuple[int, ...]]) -> str:
    """table.md of Table II at 5 humans, four planned episodes a cell, each method keeping the episodes of
    ``kept``'s indices (the others raised or ran past --episode-timeout: errors.jsonl)."""
    table2 = get_experiment("table2")
    episodes = {(method, 5): [(True, 18.0, False, False)] * 4 for method in kept}
    records = [
        r
        for r in _records(table2, episodes)
        if int(r["key"].rsplit("/", 1)[1]) in kept[r["method"]]  # key: CELL/i
    ]
    return markdown_table(table2, summarize(table2, table2.cells(), records))


@pytest.mark.parametrize(
    ("kept", "words"),
    [
        # every perpendicular crossing raised: two episodes, both circles ("half and half" before)
        ({"CMPC": (0, 2), "DMPC": (0, 2)}, "2 circle crossings"),
        ({"CMPC": (1, 3), "DMPC": (1, 3)}, "2 perpendicular crossings"),
        ({"CMPC": (1,), "DMPC": (1,)}, "the perpendicular crossing"),
        ({"CMPC": (0, 2), "DMPC": (0, 1)}, "circle and perpendicular crossings in other numbers per column"),
    ],
)
def test_the_note_counts_the_crossings_recorded(kept, words):
    assert f" per cell, {words}, the same seeds in every cell;" in _note(kept)


@pytest.mark.parametrize(
    ("kept", "words"),
    [
        ({"CMPC": (0, 1, 2, 3), "DMPC": (0, 1)}, "half circle and half perpendicular crossing"),
        ({"CMPC": (0,), "DMPC": (0,)}, "the circle crossing"),
        ({"CMPC": (0, 1, 2), "DMPC": (0, 1, 2)}, "2 circle and 1 perpendicular crossings"),
        ({"CMPC": (0, 1, 2), "DMPC": (0, 1)}, "circle and perpendicular crossings in turn, the circle first"),
    ],
)
def test_a_plans_first_episodes_read_as_before(kept, words):
    assert f" per cell, {words}, the same seeds in every cell;" in _note(kept)
