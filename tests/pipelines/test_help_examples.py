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


def _leaves(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    """(command words, parser) of every command that runs: one without actions under it (zoo list)."""
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not actions:
        yield path, parser
    for action in actions:
        for name, sub in action.choices.items():
            yield from _leaves(sub, (*path, name))


@pytest.mark.parametrize(
    ("path", "parser"), [pytest.param(*leaf, id=" ".join(leaf[0])) for leaf in _leaves(build_parser())]
)
def test_every_command_that_runs_has_an_example_in_its_own_help(path, parser):
    """README: "Every command has `--help` with an example". `crowdmpc zoo list --help` printed none: the
    examples were in `crowdmpc zoo --help` only. Each leaf's epilog has a line that runs it."""
    epilog = (parser.epilog or "").replace("\\\n", " ")
    assert "example" in epilog, f"`crowdmpc {' '.join(path)} --help` has no example"
    assert parser.formatter_class is argparse.RawDescriptionHelpFormatter  # the example keeps its lines
    runs = [line for line in epilog.splitlines() if _names(line.strip(), path)]
    assert runs, f"no example in `crowdmpc {' '.join(path)} --help` runs it"


def _names(line: str, path: tuple[str, ...]) -> bool:
    """Whether the example ``line`` runs the command ``path`` (its words, options between them)."""
    if not line.startswith("crowdmpc "):
        return False
    words = iter(shlex.split(line, comments=True))
    return all(word in words for word in path)


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
