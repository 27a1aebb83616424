"""table.md's layout: the paper's (a column per cell, the metrics as rows) up to MAX_CELL_COLUMNS cells, which
every shipped experiment at its own sizes keeps, and a row per cell past it: a 100-cell sweep's table had 101
columns."""

from __future__ import annotations

import dataclasses

from pipelines.experiments.cells import EXPERIMENTS, get_experiment
from pipelines.experiments.summary import summarize
from pipelines.experiments.tables import MAX_CELL_COLUMNS, markdown_table
from tests.pipelines.test_compare import _record


def _table(experiment) -> tuple[list[str], int]:
    """The table's lines (the notes above it left out) of hand-made records, two episodes a cell."""
    cells = experiment.cells()
    records = [
        _record(i, i == 0, False, 20.0 + i) | {"cell": cell.key, "key": f"{cell.key}/{i}"}
        for cell in cells
        for i in range(2)
    ]
    text = markdown_table(experiment, summarize(experiment, cells, records))
    lines = text.splitlines()
    return lines[next(i for i, line in enumerate(lines) if line.startswith("| ")) :], len(cells)


def _methods(count: int):
    """Table II with ``count`` methods: CMPC and DMPC (the paper's figures beside them), then CMPCs of
    other d_min."""
    table2 = get_experiment("table2")
    cmpc = table2.methods[0][1]
    more = tuple(
        (f"M{i}", dataclasses.replace(cmpc, mpc_overrides=(("d_min", 0.9 + i / 100),)))
        for i in range(count - 2)
    )
    return dataclasses.replace(table2, methods=table2.methods + more)


def test_the_shipped_experiments_keep_the_papers_layout():
    for experiment in EXPERIMENTS.values():
        lines, cells = _table(experiment)
        assert cells <= MAX_CELL_COLUMNS and lines[0].startswith("| Metrics \\ Methods | "), experiment.name
        assert lines[0].count(" | ") == cells and lines[1] == "|---|" + "---|" * cells
    lines, cells = _table(get_experiment("table2"))
    assert cells == 10 and "| &nbsp;&nbsp;paper | " in "\n".join(lines)


def test_past_the_limit_a_cell_is_a_row():
    lines, cells = _table(_methods(20))  # 20 methods at 5 crowd sizes
    assert cells == 100
    header = lines[0].removeprefix("| ").removesuffix(" |").split(" | ")
    assert header[:4] == ["Methods", "Numbers of pedestrians", "Success rate (%)", "Success rate (%), paper"]
    assert lines[1] == "|---|" + "---|" * (len(header) - 1) and len(lines) == 2 + cells
    assert all(line.count(" | ") == len(header) - 1 for line in lines[2:])  # every row as wide as the header
    rows = [line.removeprefix("| ").split(" | ") for line in lines[2:]]
    assert [r[:2] for r in rows[:3]] == [["CMPC", "5"], ["DMPC", "5"], ["M0", "5"]]
    assert rows[-1][:2] == ["M17", "9"] and "Episodes" in header
    assert rows[0][header.index("Episodes")] == "2"


def test_the_limit_is_the_last_count_in_columns():
    lines, cells = _table(dataclasses.replace(_methods(4), humans=(5, 6, 7, 8)))
    assert cells == MAX_CELL_COLUMNS and lines[0].startswith("| Metrics \\ Methods | ")
    lines, cells = _table(dataclasses.replace(_methods(17), humans=(7,)))
    assert cells == MAX_CELL_COLUMNS + 1 and lines[0].startswith("| Methods | Numbers of pedestrians | ")
