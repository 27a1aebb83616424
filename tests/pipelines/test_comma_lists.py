"""Comma lists on the command line (--humans, --alpha, --times, --predictors, --controllers): an empty item
(``2,``, ``5,,7``) may stand for a value left out, so each option refuses it in argparse's one line; it had
been dropped, and ``--humans 2,`` ran as ``--humans 2``."""

from __future__ import annotations

import argparse

import pytest

from pipelines.cli import main
from pipelines.commands import comma_items, humans_list


@pytest.mark.parametrize(
    "text, items", [("5", ["5"]), ("5,6,7", ["5", "6", "7"]), (" 5 , 6 ", ["5", "6"]), ("a,b", ["a", "b"])]
)
def test_items_are_stripped(text, items):
    assert comma_items(text) == items


@pytest.mark.parametrize("text", ["2,", ",2", "5,,7", "5, ,7", " , "])
def test_an_empty_item_is_refused(text):
    with pytest.raises(argparse.ArgumentTypeError, match="an empty item in .*single commas"):
        comma_items(text)


@pytest.mark.parametrize("text", ["", "  "])
def test_no_values_at_all_is_refused(text):
    with pytest.raises(argparse.ArgumentTypeError, match="expected values separated by commas"):
        comma_items(text)


def test_humans_keep_their_order_and_checks():
    assert humans_list("7, 5") == (7, 5)
    with pytest.raises(argparse.ArgumentTypeError, match="names 5 more than once"):
        humans_list("5,5")


@pytest.mark.parametrize(
    "argv, option",
    [
        (["sweep", "--experiment", "table2", "--humans", "2,", "--out", "{out}", "--dry-run"], "--humans"),
        (
            ["sweep", "--experiment", "predictors", "--predictors", "constant_velocity,", "--out", "{out}"],
            "--predictors",
        ),
        (
            ["sweep", "--experiment", "table2", "--controllers", "cmpc,,orca", "--out", "{out}"],
            "--controllers",
        ),
        (["calibrate", "--predictor", "constant_velocity", "--alpha", "0.1,", "--out", "{out}"], "--alpha"),
        (["review", "{out}", "--plot", "{out}/p.png", "--times", "0,,4"], "--times"),
    ],
)
def test_each_option_refuses_an_empty_item_in_one_line(argv, option, tmp_path, capsys):
    with pytest.raises(SystemExit) as done:
        main([arg.replace("{out}", str(tmp_path)) for arg in argv])
    err = capsys.readouterr().err
    assert done.value.code == 2 and err.count("\n") == 1
    assert f"argument {option}: an empty item in " in err
    assert list(tmp_path.iterdir()) == []  # refused before anything was written
