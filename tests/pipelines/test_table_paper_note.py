"""The paper's figures beside columns of other settings: a `--vary` column of another value gets none, but a
setting applied to every column (`--set`, `--margins`, `--profile`) keeps them, and table.md must say that
they are of the paper's settings, not of the columns above them."""

from __future__ import annotations

import dataclasses

from pipelines.experiments.cells import get_experiment
from pipelines.experiments.summary import summarize
from pipelines.experiments.tables import markdown_table
from pipelines.loop.margins import parse_margins
from tests.pipelines.test_compare import _record

NOTE = "They are of the paper's settings (Table I, margins none), not of the columns above them"


def _table(experiment) -> str:
    cells = [c for c in experiment.cells() if c.n_humans == 7]
    records = [
        _record(i, True, False, 20.0) | {"cell": cell.key, "key": f"{cell.key}/{i}"}
        for cell in cells
        for i in range(2)
    ]
    table = markdown_table(experiment, summarize(experiment, cells, records))
    assert "| &nbsp;&nbsp;paper | " in table  # the paper's rows are there in every case below
    return table


def test_the_paper_rows_beside_table_i_settings_carry_no_note():
    assert NOTE not in _table(get_experiment("table2"))


def test_the_paper_rows_beside_other_settings_say_whose_they_are():
    table2 = get_experiment("table2")
    overridden = tuple(
        (label, dataclasses.replace(spec, mpc_overrides=(("d_min", 0.9),))) for label, spec in table2.methods
    )
    assert NOTE in _table(dataclasses.replace(table2, methods=overridden))  # --set mpc.d_min=0.9
    assert NOTE in _table(table2.with_margins(parse_margins("fixed:0.1,0.1,0.1,0.1")))  # --margins
    world = dataclasses.replace(table2.world, profile="v1")
    assert NOTE in _table(table2.with_world(world))  # --profile v1
