"""What every ``--help`` says of each option: a help text, and the default of an option that has one, as
argparse holds it (a help stating another default is the kind of fault these catch)."""

import argparse
import re

import pytest

from pipelines.cli import build_parser

# argparse's own: --help, --version and the choice of a command
SELF_EXPLAINED = (argparse._HelpAction, argparse._VersionAction, argparse._SubParsersAction)


def _options():
    """(command words, option) of every argument of every parser, the top level's included."""

    def walk(parser: argparse.ArgumentParser, path: tuple[str, ...]):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    yield from walk(sub, (*path, name))
            elif not isinstance(action, SELF_EXPLAINED):
                yield path, action

    return list(walk(build_parser(), ()))


def _id(path: tuple[str, ...], action: argparse.Action) -> str:
    return " ".join(["crowdmpc", *path, action.option_strings[0] if action.option_strings else action.dest])


OPTIONS = [pytest.param(path, action, id=_id(path, action)) for path, action in _options()]


@pytest.mark.parametrize(("path", "action"), OPTIONS)
def test_every_option_of_every_command_has_a_help(path, action):
    """`crowdmpc calibrate --help` listed --source with its choices and no word of what it chooses, `data
    synth`'s --scenario neither what it is nor its default, `train`'s --val and --test nothing at all."""
    assert action.help and action.help.strip(), f"`{_id(path, action)}` has no help text"


def _shown(default: object) -> str:
    """A default as a help text writes it: a tuple of values comma-separated (calibrate --alpha 0.1,0.05)."""
    return ",".join(map(str, default)) if isinstance(default, tuple) else str(default)


@pytest.mark.parametrize(("path", "action"), OPTIONS)
def test_an_option_with_a_default_says_it_in_its_help(path, action):
    """An option whose default is a value (not None: resolved later, often from a config or a run) says
    that value: "(default 7)", "default: circle"."""
    if action.default in (None, False, [], argparse.SUPPRESS) or action.nargs == 0:
        return
    said = re.search(rf"default:? {re.escape(_shown(action.default))}\b", action.help or "")
    assert said, f"`{_id(path, action)}` defaults to {action.default!r}; its help says {action.help!r}"


# a help that is a range or a default and nothing more: simulate's --humans "0..50 (default: 7)"
ONLY_RANGE_OR_DEFAULT = re.compile(r"^[\d.\s]*(\.\.[\d.\s]*)?(\(default: [^)]*\))?$|^default: ")


def _meaning(help_text: str) -> list[str]:
    """The words of a help outside its parentheses and its "default ..." clauses: what the option is."""
    previous = None
    while previous != help_text:  # innermost parentheses first, so nested ones go too
        previous, help_text = help_text, re.sub(r"\([^()]*\)", " ", help_text)
    help_text = re.sub(r"\bdefault:? [^;]*", " ", help_text)
    return [word for word in help_text.split() if re.search(r"[A-Za-z]", word)]


@pytest.mark.parametrize(("path", "action"), OPTIONS)
def test_a_help_says_what_its_option_is(path, action):
    """simulate's --humans said "0..50 (default: 7)", --episodes "default: 1", --scenario "default:
    circle", sweep's --experiment "required (here or as [sweep] experiment)" and calibrate's --controller
    "closed-loop (default cmpc)": a range, a default or a condition, not what the option sets."""
    said = action.help or ""
    assert not ONLY_RANGE_OR_DEFAULT.match(said), f"`{_id(path, action)}`'s help {said!r} is a range/default"
    assert len(_meaning(said)) >= 2, f"`{_id(path, action)}`'s help {said!r} does not say what it is"


def test_the_episodes_per_cell_help_says_which_crossing_each_episode_is():
    """`sweep --help` and the [sweep] episodes_per_cell key said "half of each scenario": episode i of a cell
    is SCENARIOS[i % 2], so 1 episode is a circle alone and 3 are two circles and one perpendicular."""
    from pipelines.config.sweep_keys import sweep_keys
    from pipelines.experiments.tasks import SCENARIOS

    assert SCENARIOS == ("circle", "perpendicular")  # what the words below say
    helps = [action.help for path, action in _options() if "--episodes-per-cell" in action.option_strings]
    note = next(k.note for k in sweep_keys() if k.name == "episodes_per_cell")
    assert helps
    for text in [*helps, note]:
        assert "half of each scenario" not in text
        assert "circle and perpendicular crossings in turn, the circle first" in text


def test_train_and_evaluate_choose_the_prepared_files_with_one_data_dir_and_dataset():
    """`train` and `evaluate` each wrote --data-dir and --dataset out (duplicates D4): both take
    train_data's ``data_dir_option`` and ``dataset_option``, so their help and choices cannot drift apart."""
    from pipelines.commands import train_data

    def described(actions) -> dict:
        return {
            a.dest: (a.option_strings, a.type, a.default, a.choices, a.help)
            for a in actions
            if a.dest in ("data_dir", "dataset")
        }

    expected = argparse.ArgumentParser()
    train_data.data_dir_option(expected)
    train_data.dataset_option(expected)
    assert len(described(expected._actions)) == 2
    for command in ("train", "evaluate"):
        actions = [action for path, action in _options() if path == (command,)]
        assert described(actions) == described(expected._actions), command
