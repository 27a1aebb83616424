"""README.md's command tour: a row for every command ``crowdmpc --help`` lists, none for one it does not, and
every option a row names is one its command takes."""

import argparse
import re
from pathlib import Path

from pipelines.cli import COMMANDS, build_parser

README = Path(__file__).resolve().parents[2] / "README.md"
OPTION = re.compile(r"(?:(\w+)'s )?`?(--[a-z][a-z-]*)")


def _rows() -> dict[str, str]:
    """Each row of the tour's table by the command its first cell runs."""
    tour = README.read_text().split("## Command tour", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in tour.splitlines():
        found = re.match(r"\| `crowdmpc (\w+)", line)
        if found:
            rows[found.group(1)] = line
    return rows


def _options(parser: argparse.ArgumentParser) -> set[str]:
    """The options of ``parser`` and of its actions (zoo calibrations --plot)."""
    found: set[str] = set()
    for action in parser._actions:
        found |= set(action.option_strings)
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                found |= _options(sub)
    return found


def test_the_command_table_has_a_row_for_each_command():
    """`cache` and `config` had none: a reader of the tour met `crowdmpc cache info|clear` only inside
    sweep's row and `config show` not at all."""
    assert sorted(_rows()) == sorted(COMMANDS)


def test_every_option_a_row_names_is_its_commands():
    """An option written "simulate's `--sensor-range`" is simulate's, whatever row names it."""
    parser = build_parser()
    (commands,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    own = {option for action in parser._actions for option in action.option_strings}
    for command, row in _rows().items():
        for owner, option in OPTION.findall(row):
            takes = _options(commands.choices[owner or command]) | own
            assert option in takes, (
                f"README's row of {command} names {option}, which {owner or command} lacks"
            )
