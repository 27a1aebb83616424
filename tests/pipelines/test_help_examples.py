"""Every example that ``crowdmpc --help`` and its commands' ``--help`` print parses as printed (a renamed flag
or a misspelled command fails here) and keeps its line breaks (running them is a walkthrough's job)."""

import argparse
import re
import shlex

import pytest

from pipelines.cli import COMMANDS, build_parser


def _epilogs(parser: argparse.ArgumentParser) -> list[str]:
    """The help epilogs of ``parser`` and of every command and action under it."""
    found = [parser.epilog] if parser.epilog else []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                found += _epilogs(sub)
    return found


def _examples() -> list[str]:
    """Each ``crowdmpc ...`` line, continuations joined, a shell redirection and a comment dropped. Lines with
    ``--plugin`` are left out: they name a module of the reader's (``my_predictor:MyNet``), and parsing one
    imports it (tests/pipelines/test_cli_plugins.py runs real plugins)."""
    lines = []
    for epilog in _epilogs(build_parser()):
        for line in epilog.replace("\\\n", " ").splitlines():
            line = line.strip().split(" > ")[0]
            if line.startswith("crowdmpc ") and "--plugin" not in line:
                lines.append(line)
    return lines


EXAMPLES = _examples()


def test_the_help_texts_have_examples_of_every_command():
    assert set(COMMANDS) <= {_command(line) for line in EXAMPLES}


def _command(line: str) -> str:
    """The command word of an example (after any --config/--set given before it)."""
    words = shlex.split(line, comments=True)[1:]
    while words and words[0].startswith("--"):
        words = words[2:]
    return words[0]


def test_no_example_lost_its_line_break():
    """A continuation written ``\\`` where ``\\\\`` was needed vanishes from the help text and leaves one
    line with a run of spaces before the next option (``... controllers       --controllers ...``)."""
    for epilog in _epilogs(build_parser()):
        for line in epilog.splitlines():
            if line.strip().startswith("crowdmpc "):
                assert not re.search(r"\S {4,}--", line), f"a swallowed line break in: {line.strip()}"


@pytest.mark.parametrize("line", EXAMPLES)
def test_every_help_example_parses(line, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = build_parser().parse_args(shlex.split(line, comments=True)[1:])
    assert getattr(args, "func", None) is not None, f"{line!r} names no command that runs"
