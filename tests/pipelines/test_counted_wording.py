"""One robot and one human are counted in the singular wherever a line or a label counts them (export's
printout said "1 humans, 1 robots" until 29d4840f; its helper, predictors.text_table.counted, now serves
every such line): runs of one robot or one human are allowed."""

import dataclasses
import types

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec
from predictors.text_table import counted


def test_counted_says_one_in_the_singular_and_any_other_number_in_the_plural():
    assert [counted(n, "human") for n in (0, 1, 2)] == ["0 humans", "1 human", "2 humans"]


def test_the_note_on_a_large_nlp_counts_one_robot_and_one_human():
    from pipelines.commands.simulate_checks import size_note

    spec = ControllerSpec("cmpc", "constant_velocity", mpc_overrides=(("horizon", 13),))
    assert (size_note(spec, 1, 1) or "").startswith("note: an NLP of 1 robot among 1 human over 13 steps ")


def test_a_history_of_the_wrong_shape_counts_one_robot_and_one_human():
    from pipelines.loop.mpc_setup import check_history

    obs = CrowdEnv().reset(0, "circle", 1, n_robots=1)
    with pytest.raises(PipelineError, match=r"the last L positions of the 1 robot then the 1 human, in"):
        check_history(dataclasses.replace(obs, history=np.zeros((8, 3, 2))))


def test_a_sweeps_notes_on_cells_of_one_human_count_it_so():
    from pipelines.commands.sweep_table_notes import not_counted_note

    cell = types.SimpleNamespace(key="c", method="CMPC", n_humans=1)
    tasks = [types.SimpleNamespace(cell=cell) for _ in range(4)]
    assert not_counted_note((cell,), tasks, {"c": 3}).startswith(
        "Not counted, planned episodes not recorded: CMPC at 1 human 1 of 4"
    )


def test_compares_method_ticks_count_one_human_and_one_robot():
    from pipelines.experiments.compare_plot import _ticks

    groups = [{"method": "cmpc", "humans": 1, "robots": 1}]
    assert _ticks(groups, by_humans=False) == {"cmpc": "cmpc\n1 human, 1 robot"}
    teams = [{"method": "cmpc", "humans": 5, "robots": r} for r in (1, 3)]  # a list: "robots" as before
    assert _ticks(teams, by_humans=False) == {"cmpc": "cmpc\n5 humans, 1, 3 robots"}


def test_a_dry_runs_cells_of_one_human_are_counted_so_and_stay_in_line(tmp_path, capsys):
    from pipelines.cli import main

    out = tmp_path / "out"
    assert main(["sweep", "--experiment", "table2", "--humans", "1,10", "--dry-run", "--out", str(out)]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if "-r3" in line]
    assert [row.split()[1:3] for row in rows[::2]] == [["1", "human"], ["10", "humans"]]
    assert len({row.index("cmpc-") if "cmpc-" in row else row.index("dmpc-") for row in rows}) == 1
