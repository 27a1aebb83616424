"""A config file's entries, ``--set`` overrides and the command line's options (``pipelines.config.entries``)
validated into one ``RunConfig``.

Precedence, lowest first: the dataclasses' defaults, the TOML file, ``--set SECTION.KEY=VALUE`` (in order;
``--set SECTION.KEY=null`` unsets the key), the command's explicit options (``--humans 5``). Every value is
checked by the dataclass it belongs to; an error is one line naming where the value came from, the key and
what is expected:

    run.toml: mpc.horizon: must be an integer >= 1, got 'four'
    --set mpc.horizon: must be an integer >= 1, got 0
    --humans: n_humans must be in [0, 50], got 60
"""

from __future__ import annotations

import re
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final

from crowdsim.env import EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.orca import OrcaParams
from crowdsim.world import WorldFacts
from mpc.config import MPCConfig
from mpc.errors import MPCConfigError
from pipelines.config.entries import ConfigError, Entry, Source, long_number, reason
from pipelines.config.schema import SECTION_BY_NAME, SECTIONS, WRITE_ORDER, Key, Section
from pipelines.config.settings import (
    ControllerSettings,
    ScenarioSettings,
    SimulateSettings,
    SweepSettings,
)
from pipelines.errors import PipelineError
from predictors.errors import PredictorError

# What the dataclasses raise for a bad value.
VALUE_ERRORS: Final[tuple[type[Exception], ...]] = (
    PipelineError,
    SimulationError,
    MPCConfigError,
    PredictorError,
)


def _named_field(message: str, section: Section) -> str | None:
    """The key a dataclass message is about, when it starts with one of the section's keys."""
    match = re.match(r"(?:[A-Za-z_]\w*\.)?(\w+) must", message)
    return match[1] if match and match[1] in section.names else None


_KIND_TEXT: Final[Mapping[str, str]] = {
    "int": "an integer",
    "float": "a number",
    "bool": "true or false",
    "str": "a string",
    "ints": "a list of integers, like [5, 6, 7]",
    "strs": "a list of names",  # like the key's example (controllers are no predictors' names)
}


def _coerce(key: Key, value: Any) -> tuple[bool, Any]:
    """(ok, value as the dataclass takes it): TOML integers become floats where a float is expected, lists
    become tuples."""
    if key.kind == "bool":
        return isinstance(value, bool), value
    if key.kind == "int":
        return isinstance(value, int) and not isinstance(value, bool), value
    if key.kind == "float":
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        return ok, float(value) if ok else value
    if key.kind == "str":
        return isinstance(value, str), value
    item = str if key.kind == "strs" else int
    ok = isinstance(value, list) and all(isinstance(v, item) and not isinstance(v, bool) for v in value)
    return ok, tuple(value) if ok else value


def _short(value: Any) -> str:
    """``value`` in an error line: its repr, cut to 80 characters."""
    try:
        text = repr(value)
    except ValueError:  # an integer (or a list holding one) with more digits than Python writes
        return long_number()
    return text if len(text) <= 80 else text[:77] + "..."


def _unwritable(value: Any) -> bool:
    """An integer (or a list holding one) with more digits than Python writes in decimal."""
    try:
        repr(value)
    except ValueError:
        return True
    return False


def _shortened(message: str, values: Iterable[Any]) -> str:
    """``message`` (a dataclass's) with each long value it shows in full cut as ``_short`` cuts it: a 900 kB
    string in a file is no 900 kB error line."""
    for value in values:  # TOML values, whose repr _value has checked; a list's items shown alone too
        for shown in (value, *value) if isinstance(value, list | tuple) else (value,):
            text = repr(shown)
            if len(text) > 80:
                message = message.replace(text, _short(shown))
    return message


@dataclass
class _Resolver:
    chosen: dict[str, dict[str, Any]]  # section -> key -> value (set somewhere)
    sources: dict[tuple[str, str], Source]
    built: dict[str, Any] = field(default_factory=dict)
    values: dict[str, dict[str, Any]] = field(default_factory=dict)

    def build(self, section: Section) -> Any:
        chosen = self.chosen.get(section.name, {})
        values: dict[str, Any] = {k.name: k.default for k in section.keys}
        for name, raw in chosen.items():
            key = section.key(name)
            assert key is not None  # read_file and parse_set refuse unknown keys
            values[name] = self._value(section, key, raw, values)
        try:
            obj = section.build(values, self.built)
        except VALUE_ERRORS as exc:
            raise self._attribute(section, values, str(exc)) from None
        self.built[section.name] = obj
        self.values[section.name] = values
        return obj

    def _value(self, section: Section, key: Key, raw: Any, values: dict[str, Any]) -> Any:
        """``raw`` as the dataclass takes it, or the one-line error: a number no record could hold, the wrong
        type, above the key's ceiling."""
        label = self.sources[(section.name, key.name)].label
        if _unwritable(raw):  # config show, and every record's JSON, could not write it
            raise ConfigError(label(section.name, key.name, long_number()))
        try:
            ok, value = _coerce(key, raw)
        except OverflowError:  # an integer past the largest float (TOML's 1e400 is inf: "must be finite")
            message = f"{key.name} must be at most {sys.float_info.max:.2g} in magnitude, got {_short(raw)}"
            raise ConfigError(label(section.name, key.name, message)) from None
        if not ok:
            raise self._kind_error(section, key, raw, values)
        if key.most is not None and value > key.most:  # a number that sizes the work
            most = key.most if key.kind == "float" else int(key.most)
            raise ConfigError(
                label(section.name, key.name, f"{key.name} must be at most {most}, got {_short(value)}")
            )
        return value

    def _kind_error(self, section: Section, key: Key, raw: Any, defaults: dict[str, Any]) -> ConfigError:
        """The dataclass's own message for a value of the wrong type when it names the key (MPCConfig's
        "must be an integer >= 1, got 'four'"), else "must be an integer, got 'four'"."""
        text = _KIND_TEXT[key.kind]
        if key.kind == "strs" and isinstance(key.example, list):
            text += ", like [" + ", ".join(f'"{name}"' for name in key.example) + "]"
        message = f"{key.name} must be {text}, got {_short(raw)}"
        if key.kind == "bool":  # TOML's spelling, whatever the dataclass says ("True or False", "a bool")
            return ConfigError(self.sources[(section.name, key.name)].label(section.name, key.name, message))
        try:
            section.build({**defaults, key.name: raw}, self.built)
        except VALUE_ERRORS as exc:  # its own wording, when it is about this key and shows the value
            if _named_field(str(exc), section) == key.name and repr(raw) in str(exc):
                message = _shortened(str(exc), [raw])
        except (TypeError, ValueError, AttributeError):
            pass
        return ConfigError(self.sources[(section.name, key.name)].label(section.name, key.name, message))

    def _attribute(self, section: Section, values: dict[str, Any], message: str) -> ConfigError:
        """A one-line error for a section that does not validate: the key the message names, else the first
        chosen key that breaks it alone, else the last chosen key the message names (a clash of two chosen
        values), else the last chosen one."""
        chosen = self.chosen.get(section.name, {})
        message = _shortened(message, [values[name] for name in chosen])
        culprit = _named_field(message, section)
        defaults = {k.name: k.default for k in section.keys}
        # The section's defaults break too: a value of a section built before does ([world] dt = 1e-9 is
        # below EnvConfig's least dt), not this one's chosen values (--set env.time_limit=1e-6 was blamed).
        earlier = culprit is None and not _builds(section, defaults, self.built)
        if culprit is None and not earlier:
            for name in chosen:
                try:
                    section.build({**defaults, name: values[name]}, self.built)
                except VALUE_ERRORS:
                    culprit = name
                    break
                except Exception:  # noqa: BLE001 - only locating the key here
                    continue
            if culprit is None:  # a clash of chosen values: the last one the message names, else the last
                named = [name for name in chosen if re.search(rf"\b{re.escape(name)}\b", message)]
                culprit = named[-1] if named else (list(chosen)[-1] if chosen else None)
        source = None if culprit is None else self.sources.get((section.name, culprit))
        if source is not None:
            return ConfigError(source.label(section.name, culprit or "", message))
        # A default that clashes with a chosen value (of this section, or of one built before, [world]):
        # "run.toml: env.time_limit: env.timeout_margin (unset: the paper profile's 1.0): must be ...".
        # The chosen value the message names first ("dt = 0.0001 s" is [world] dt's), not a bystander set
        # after it (--set env.orca.max_neighbors=5 was blamed for [world] dt's episode length).
        here = [((section.name, name), self.sources[(section.name, name)]) for name in chosen]
        before = [(k, src) for k, src in self.sources.items() if k[0] in self.built]
        said = [(k, src) for k, src in (*before, *here) if re.search(rf"\b{re.escape(k[1])}\b", message)]
        clash = said or (before if earlier else here) or before
        lead = ""
        if clash:
            (clash_section, clash_key), src = clash[-1]
            lead = (src.where if src.kind == "cli" else src.prefix(clash_section, clash_key)) + ": "
        if culprit is None:
            return ConfigError(f"{lead}[{section.name}]: {message}")
        shown = f"{section.name}.{culprit} (unset: {_unset_value(section, culprit, values)})"
        return ConfigError(f"{lead}{shown}: {reason(message, culprit)}")


def _builds(section: Section, values: dict[str, Any], built: Mapping[str, Any]) -> bool:
    """Whether ``section`` validates with ``values`` over the sections ``built``."""
    try:
        section.build(values, built)
    except Exception:  # noqa: BLE001 - only asking whether it builds
        return False
    return True


def _unset_value(section: Section, key: str, values: Mapping[str, Any]) -> str:
    """What an unset key stands for: an [env] key its profile's value, others their default."""
    if section.name == "env":
        from crowdsim.profiles import PROFILES

        profile = str(values.get("profile"))
        value = getattr(PROFILES.get(profile, PROFILES["paper"]), key, None)
        return f"the {profile} profile's {_short(value)}"
    k = section.key(key)
    return _short(None if k is None else k.default)


@dataclass(frozen=True)
class RunConfig:
    """The effective configuration of a run: every section validated, and where each chosen value came
    from."""

    world: WorldFacts
    orca: OrcaParams
    env: EnvConfig
    scenario: ScenarioSettings
    controller: ControllerSettings
    mpc: MPCConfig  # Table I in `world`, then [mpc]; flocking and margins are applied by the controller
    simulate: SimulateSettings
    sweep: SweepSettings
    values: Mapping[str, Mapping[str, Any]]  # section -> key -> value (None: unset)
    sources: Mapping[tuple[str, str], Source]  # (section, key) -> where a chosen value came from
    path: str | None = None  # the config file, if any

    def source(self, section: str, key: str) -> Source | None:
        return self.sources.get((section, key))

    def default(self, section: str, key: str) -> Any:
        k = SECTION_BY_NAME[section].key(key)
        if k is None:
            raise KeyError(f"{section}.{key}")
        if section == "mpc":  # Table I in this config's world
            return getattr(MPCConfig.from_world(self.world), key)
        return k.default

    def chosen(self, section: str, key: str) -> bool:
        """Whether the run asks for this value: given as an option or a ``--set`` item (each names the value
        on purpose, the default too, so a sweep refuses ``--set controller.flocking=true`` for table3 as it
        does ``=false``), or set in a file to something else than the default (a file written by ``config
        show`` states every default, and chooses nothing by it)."""
        source = self.sources.get((section, key))
        if source is None:
            return False
        return source.kind != "file" or self.values[section][key] != self.default(section, key)

    def label(self, section: str, key: str) -> str:
        """How an error about this value names it: "run.toml: sweep.out", "--out", "--set sweep.out"."""
        source = self.sources.get((section, key))
        if source is None:
            return f"{section}.{key}"
        return source.where if source.kind == "cli" else source.prefix(section, key)

    def error(self, section: str, key: str, message: str) -> ConfigError:
        """A one-line error about this value (``message`` says what is wrong, starting with "must" or not)."""
        source = self.sources.get((section, key))
        if source is None:
            return ConfigError(f"{section}.{key}: {message}")
        if source.kind == "cli":
            return ConfigError(f"{source.where}: {message}")
        return ConfigError(f"{source.prefix(section, key)}: {message}")

    def mpc_overrides(self) -> tuple[tuple[str, Any], ...]:
        """The [mpc] values that differ from Table I in this world: ``ControllerSpec.mpc_overrides``."""
        table_i = MPCConfig.from_world(self.world)
        return tuple(
            (name, value) for name, value in self.values["mpc"].items() if value != getattr(table_i, name)
        )

    def effective(self) -> dict[str, dict[str, Any]]:
        """Every section's effective values, for records and metadata: the unset [env] keys as the profile
        gives them, other unset keys as null."""
        out = {name: dict(self.values[name]) for name in WRITE_ORDER}
        for name in out["env"]:
            if out["env"][name] is None:
                out["env"][name] = getattr(self.env, name)
        return out


def resolve(entries: Iterable[Entry], path: str | None = None) -> RunConfig:
    """Validate ``entries`` (later ones override earlier ones) over the defaults."""
    chosen: dict[str, dict[str, Any]] = {}
    sources: dict[tuple[str, str], Source] = {}
    for entry in entries:
        if entry.value is None:  # --set KEY=null: unset, as if no entry before had set it
            chosen.get(entry.section, {}).pop(entry.key, None)
            sources.pop((entry.section, entry.key), None)
            continue
        chosen.setdefault(entry.section, {})[entry.key] = entry.value
        sources[(entry.section, entry.key)] = entry.source
    resolver = _Resolver(chosen, sources)
    for section in SECTIONS:
        resolver.build(section)
    built = resolver.built
    return RunConfig(
        world=built["world"],
        orca=built["env.orca"],
        env=built["env"],
        scenario=built["scenario"],
        controller=built["controller"],
        mpc=built["mpc"],
        simulate=built["simulate"],
        sweep=built["sweep"],
        values=resolver.values,
        sources=sources,
        path=path,
    )
