"""A command's effective config: its ``--config`` file, ``--set`` items and the options given explicitly
(defaults < file < ``--set`` < options), each option mapped onto its config key."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from pipelines.config.entries import ConfigError, Entry, Source, parse_set, read_file
from pipelines.config.resolve import RunConfig, resolve
from predictors.errors import short_repr


@dataclass(frozen=True)
class Option:
    """A command-line option that sets a config key when given (its argparse default is None). A path option
    takes text, not ``type=Path``: ``Path("")`` is ".", so ``--record ""`` would write to the current
    directory instead of being refused as the config file's ``record = ""`` is."""

    dest: str
    section: str
    key: str
    flag: str
    convert: Any = None  # value -> the key's value (e.g. --no-flocking -> flocking = false)


def cli_entries(args: Any, options: Sequence[Option]) -> list[Entry]:
    entries = []
    for option in options:
        value = getattr(args, option.dest, None)
        if value is None:
            continue
        if option.convert is not None:
            value = option.convert(value)
        if isinstance(value, tuple):
            value = list(value)
        entries.append(Entry(option.section, option.key, value, Source("cli", option.flag)))
    return entries


def _given(value: Any) -> list[Any]:
    """An option's values: None, one value, or a list (an ``append`` option, given more than once). An empty
    one is kept: ``--config ""`` is refused as a missing file, not taken for no file."""
    if isinstance(value, list | tuple):
        return [v for v in value if v is not None]
    return [] if value is None else [value]


def _same(path: str) -> str:
    """What a config path names, for telling two spellings of one file apart from two files."""
    try:
        return os.path.realpath(path)
    except (OSError, ValueError):  # a NUL byte: refused as it is read
        return path


def config_arguments(args: Any) -> tuple[str | None, list[str]]:
    """The config file and ``--set`` items of a command line: before the command (``crowdmpc --config F``)
    or after it (``crowdmpc simulate --config F``); one file at most (the same one twice is one)."""
    given = [*_given(getattr(args, "config_file", None)), *_given(getattr(args, "sub_config_file", None))]
    files = list(dict.fromkeys(str(f) for f in given))
    if len(files) > 1 and len({_same(f) for f in files}) == 1:  # a.toml and ./a.toml: one file
        files = files[:1]
    if len(files) > 1:
        raise ConfigError(f"--config given twice ({files[0]}, {files[1]}); one config file per run")
    sets = [*(getattr(args, "config_set", None) or []), *(getattr(args, "sub_config_set", None) or [])]
    return (str(files[0]) if files else None), sets


def load(path: str | None = None, sets: Sequence[str] = (), cli: Sequence[Entry] = ()) -> RunConfig:
    """Defaults < the file at ``path`` < ``sets`` < ``cli``, validated."""
    if path is not None and not isinstance(path, str | os.PathLike):
        raise ConfigError(f"the config file must be a path, got {short_repr(path)}")
    # a string is a sequence too: "mpc.horizon=3" was read letter by letter ("--set 'm': expected ...")
    if isinstance(sets, str) or not isinstance(sets, Sequence) or not all(isinstance(t, str) for t in sets):
        raise ConfigError(f"sets must be a list of 'SECTION.KEY=VALUE' strings, got {short_repr(sets)}")
    entries = read_file(path) if path is not None else []
    entries += [parse_set(text) for text in sets]
    entries += list(cli)
    return resolve(entries, path)


def command_config(args: Any, options: Sequence[Option] = ()) -> RunConfig:
    """The effective config of a command: its --config file, --set items and explicit ``options``."""
    path, sets = config_arguments(args)
    return load(path, sets, cli_entries(args, options))
