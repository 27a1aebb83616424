"""A config's values as entries, each with where it came from: a TOML config file read and checked against the
schema's sections and keys (``read_file``), a ``--set SECTION.KEY=VALUE`` item parsed (``parse_set``), and the
one-line error that names a value by its source (``Source.label``). ``pipelines.config.resolve`` validates
the entries into a ``RunConfig``.
"""

from __future__ import annotations

import datetime
import difflib
import errno
import re
import stat
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Literal

from pipelines.config.schema import SECTION_BY_NAME, WRITE_ORDER, Section
from pipelines.errors import PipelineError

MAX_CONFIG_BYTES: Final[int] = 1 << 20  # a config file is a page of settings, never a megabyte


class ConfigError(PipelineError):
    """A config file, ``--set`` or option that cannot be used: one line naming it."""


@dataclass(frozen=True)
class Source:
    """Where a value came from: a config file, ``--set``, or a command-line option."""

    kind: Literal["file", "set", "cli"]
    where: str  # the file's path as given, "--set", or the option ("--humans")

    def label(self, section: str, key: str, message: str) -> str:
        """The one-line error for ``message`` (a dataclass's, e.g. "horizon must be an integer >= 1, ...")."""
        if self.kind == "cli":
            match = _field_prefix(key).match(message)
            return f"{self.where} {message[match.end() :]}" if match else f"{self.where}: {message}"
        return f"{self.prefix(section, key)}: {reason(message, key)}"

    def prefix(self, section: str, key: str) -> str:
        return f"{self.where}: {section}.{key}" if self.kind == "file" else f"--set {section}.{key}"


def _field_prefix(key: str) -> re.Pattern[str]:
    """A dataclass message's leading field name: ``horizon `` or ``EnvConfig.time_limit ``."""
    return re.compile(rf"(?:[A-Za-z_]\w*\.)?{re.escape(key)} (?=must|\d)")


def reason(message: str, key: str) -> str:
    """``message`` without its leading field name when it states a requirement ("must be ...")."""
    match = _field_prefix(key).match(message)
    return message[match.end() :] if match and message[match.end() :].startswith("must") else message


@dataclass(frozen=True)
class Entry:
    section: str
    key: str
    value: Any  # None: unset (--set KEY=null)
    source: Source


def _unknown_section(where: str, name: str) -> ConfigError:
    valid = ", ".join(f"[{s}]" for s in WRITE_ORDER)
    # [controller.mpc]: its last part is the section meant ([mpc]), else the closest whole name
    last = name.rpartition(".")[2]
    close = [last] if last in WRITE_ORDER else difflib.get_close_matches(name, list(WRITE_ORDER), n=1)
    hint = f" (did you mean [{close[0]}]?)" if close and "." in name else ""
    return ConfigError(f"{where}: [{name}]: unknown section{hint}; valid sections: {valid}")


def _outside_sections(where: str, name: str) -> ConfigError:
    """A key written above every table (``horizon = 4`` before ``[mpc]``): the sections that have it, else
    the closest key of any section."""
    owners = _owners(name)
    if owners:
        put = " or ".join(f"[{s}]" for s in owners)
        return ConfigError(f"{where}: {name}: a key outside any section; put it under its section ({put})")
    owner = {key: s for s in reversed(WRITE_ORDER) for key in SECTION_BY_NAME[s].names}
    close = difflib.get_close_matches(name, list(owner), n=1)
    hint = f" (did you mean {close[0]!r} of [{owner[close[0]]}]?)" if close else ""
    valid = ", ".join(f"[{s}]" for s in WRITE_ORDER)
    return ConfigError(
        f"{where}: {name}: a key outside any section, and no section has it{hint}; valid sections: {valid}"
    )


def _owners(name: str) -> list[str]:
    """The sections that have a key ``name``, in the order a file is written."""
    return [s for s in WRITE_ORDER if SECTION_BY_NAME[s].key(name) is not None]


def check_key(prefix: str, section: Section, key: str) -> None:
    """Refuse a key the section does not have, saying where it belongs or which keys are valid."""
    if section.key(key) is not None:
        return
    if key in section.elsewhere:
        raise ConfigError(f"{prefix}: not a [{section.name}] key: {section.elsewhere[key]}")
    close = difflib.get_close_matches(key, section.names, n=1)
    owners = _owners(key)  # `episodes` under [scenario]: a key of [simulate] and [sweep]'s episodes_per_cell
    hint = (
        f" (did you mean {close[0]!r}?)"
        if close
        else f" (a key of {' and '.join(f'[{s}]' for s in owners)})"
        if owners
        else ""
    )
    raise ConfigError(f"{prefix}: unknown key{hint}; valid keys: {', '.join(section.names)}")


def _unreachable(path: Path) -> str | None:
    """Why ``path`` cannot be looked at (``Path.exists`` says False for a symbolic-link loop too)."""
    try:
        path.stat()
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return "a symbolic-link loop"
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            return "no such file"
        return f"cannot read it ({exc.strerror or exc})"
    return None


def _config_bytes(path: Path, where: str, piped: bool) -> bytes:
    """The bytes of config file ``path``; of a pipe (a shell's ``--config <(...)``, which was refused as not
    a file), read once, as it can be, and refused past 1 MiB as a file is."""
    if not piped:
        return path.read_bytes()
    with path.open("rb") as pipe:
        data = pipe.read(MAX_CONFIG_BYTES + 1)
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(f"--config {where}: more than 1 MiB from the pipe; a config file is at most 1 MiB")
    return data


def read_file(path: str | Path) -> list[Entry]:
    """The entries of a TOML config file, in file order; unknown sections and keys refused."""
    where = str(path)
    if where == "":  # Path("") is ".", a directory: say what was given
        raise ConfigError("--config '': no such file (an empty path)")
    p = Path(path)
    problem = _unreachable(p)
    if problem is not None:
        raise ConfigError(f"--config {where}: {problem}")
    piped = stat.S_ISFIFO(p.stat().st_mode)
    if not (piped or p.is_file()):
        raise ConfigError(f"--config {where}: not a file")
    if not piped and p.stat().st_size > MAX_CONFIG_BYTES:
        raise ConfigError(f"--config {where}: {p.stat().st_size} bytes; a config file is at most 1 MiB")
    try:  # utf-8-sig: a byte-order mark, which Windows editors write and TOML does not allow, is dropped
        text = _config_bytes(p, where, piped).decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ConfigError(f"{where}: not UTF-8 text (a TOML file)") from None
    except OSError as exc:
        raise ConfigError(f"--config {where}: cannot read it ({exc.strerror or exc})") from None
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{where}: not valid TOML: {exc}") from None
    except ValueError:  # not a TOMLDecodeError: a decimal integer past Python's digit limit
        raise ConfigError(f"{where}: not a config file: {long_number()}") from None
    except RecursionError:  # tomllib parses nested arrays and tables recursively
        raise ConfigError(f"{where}: not a config file: arrays or tables nested too deeply") from None
    source = Source("file", where)
    entries: list[Entry] = []

    def table(name: str, values: Any) -> None:
        section = SECTION_BY_NAME[name]
        if not isinstance(values, dict):
            raise ConfigError(f"{where}: {name}: must be a table ([{name}]), got {values!r}"[:300])
        for key, value in values.items():
            if name == "env" and key == "orca":
                table("env.orca", value)
                continue
            # A table that is no key's value ([env.orcaa]): [env.orca] is the only one there is.
            if isinstance(value, dict) and section.key(key) is None:
                raise _unknown_section(where, f"{name}.{key}")
            check_key(source.prefix(name, key), section, key)
            date = _date_in(value)
            if date is not None:
                raise ConfigError(f"{source.prefix(name, key)}: {_NO_DATE} {date.isoformat()} {_QUOTE_IT}")
            entries.append(Entry(name, key, value, source))

    for name, values in document.items():
        if name == "env.orca":  # a quoted ["env.orca"]: one name with a dot in it, not the table orca of env
            raise ConfigError(f'{where}: ["env.orca"] names no section: write [env.orca], without quotes')
        if not isinstance(values, dict) and (name not in SECTION_BY_NAME or _owners(name)):
            raise _outside_sections(where, name)  # a section's name written as a key is one (controller)
        if name not in SECTION_BY_NAME:
            raise _unknown_section(where, name)
        table(name, values)
    return entries


_NO_DATE: Final[str] = "must not be a TOML date or time, got"
_QUOTE_IT: Final[str] = '(no setting takes one; quote it, "...", for a string)'
# "=" and ";" too: a sweep's vary is KEY=V1,V2 (";" between grids), `--set sweep.vary=mpc.d_min=0.8,0.9`
BARE_VALUE: Final[re.Pattern[str]] = re.compile(r"[A-Za-z0-9_./~:,+@=;-]+")
CONTROL: Final[re.Pattern[str]] = re.compile(r"[\x00-\x08\x0a-\x1f\x7f]")  # all but the tab
UNSET: Final[str] = "null"  # --set KEY=null: the key's default, as if no file or --set before had set it


def parse_set(text: str) -> Entry:
    """``--set SECTION.KEY=VALUE``: VALUE is a TOML value (``1e6``, ``true``, ``"circle"``, ``[5, 6]``); a
    bare word that is no TOML value (``circle``, ``conformal:0.05``, ``runs/x``), or a number or date given
    bare to a text setting (``sweep.out=2026``), is taken as a string, but
    ``null``, which unsets the key (an entry of value None): TOML has no null, so a file's ``plot = "..."``
    could not be switched off from the command line (``none`` was a file name). ``null`` is what a record
    holds for an unset key, as Helm's ``--set`` and Hydra's overrides spell it; ``"null"`` is the string."""
    name, sep, raw = text.partition("=")
    name, raw = name.strip(), raw.strip()
    if not sep or "." not in name:
        raise ConfigError(f"--set {text[:80]!r}: expected SECTION.KEY=VALUE, e.g. mpc.w_coll=1e6")
    if CONTROL.search(text):  # TOML would read what follows a line break as more keys, silently ignored
        raise ConfigError(
            f"--set {text[:80]!r}: a line break or control character; one SECTION.KEY=VALUE per --set"
        )
    section_name, key = name.rsplit(".", 1)
    section = SECTION_BY_NAME.get(section_name)
    if section is None:
        raise _unknown_section(f"--set {name}", section_name)
    whole = SECTION_BY_NAME.get(name)  # env.orca=...: [env] has no key orca, a list that names none of this
    if whole is not None:
        raise ConfigError(
            f"--set {name}: [{name}] is a section; set one of its keys at a time, --set {name}.KEY=VALUE "
            f"(keys: {', '.join(whole.names)})"
        )
    check_key(f"--set {name}", section, key)
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except RecursionError:  # tomllib parses nested arrays recursively
        raise ConfigError(f"--set {name}: the value's arrays or tables are nested too deeply") from None
    except tomllib.TOMLDecodeError:
        if raw == UNSET:
            return Entry(section.name, key, None, Source("set", "--set"))
        if BARE_VALUE.fullmatch(raw) is None:
            raise ConfigError(
                f'--set {name}: {raw[:80]!r} is not a TOML value (e.g. 1e6, true, "circle", [5, 6]; '
                f"{UNSET} unsets the key)"
            ) from None
        value = raw
    except ValueError:  # not a TOMLDecodeError: a decimal integer past Python's digit limit
        raise ConfigError(f"--set {name}: {long_number()}") from None
    date = _date_in(value)
    if date is not None and BARE_VALUE.fullmatch(raw):
        value = raw  # no setting takes a date: --set simulate.json=2026-12-02 names a file, like other words
    elif date is not None:
        raise ConfigError(f"--set {name}: {_NO_DATE} {date.isoformat()} {_QUOTE_IT}")
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if number and BARE_VALUE.fullmatch(raw) and _kind(section, key) == "str":
        # a text setting takes no number: --set sweep.out=2026 names the folder --out 2026 names (it was
        # "must be a path, got 2026", and 1e3 "got 1000.0"), as a date is the word typed
        value = raw
    return Entry(section.name, key, value, Source("set", "--set"))


def _kind(section: Section, key: str) -> str | None:
    found = section.key(key)
    return None if found is None else found.kind


def _date_in(value: Any) -> datetime.date | datetime.time | None:
    """The first TOML date or time in ``value`` (arrays and inline tables searched): tomllib reads 2026-12-02
    and 07:32:00 as Python dates and times, which no setting takes, and whose ``repr`` reads as Python."""
    if isinstance(value, datetime.date | datetime.time):
        return value
    if isinstance(value, list | dict):  # an array, or an inline table
        items = value.values() if isinstance(value, dict) else value
        return next((d for d in map(_date_in, items) if d is not None), None)
    return None


def long_number() -> str:
    """What an integer is that Python will not read or write in decimal (its digit limit; TOML's 0x, 0o and
    0b integers have none, so they can be longer)."""
    return f"an integer of more than {sys.get_int_max_str_digits()} digits"
