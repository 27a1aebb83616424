"""``sweep --vary mpc.KEY=V1,V2,..``, ``--vary controller.margins=M1,M2,..``, ``--vary
scenario.robots=M1,M2,..``, ``--vary env[.orca].KEY=V1,V2,..`` or ``--vary simulate.sensor_range=R1,R2,..``
([sweep] vary): a column per value of one [mpc] setting, or per margins, beside each method that plans with a
predictor, on the same crowds, or per number of robots beside every method, on the same seeds (the humans are
placed clear of each team), or per value of a simulator setting (the humans' ORCA, the time limit, ...:
``World.env_settings``) or per sensor range (``World.sensing``) beside every method, in one table.

Each column is the cell ``--set mpc.KEY=V`` (``--margins M``, ``--robots M``, ``--set env.KEY=V``,
``--sensor-range R``) makes (its key, its episodes): a value that is Table I's (margins none, the paper's 3
robots, the profile's own simulator value) adds nothing to the cell, whose episodes are those of the sweep
without ``--vary``, so a study can extend a sweep already run. Every value is checked as ``--set``
(``--margins``, ``--robots``) checks it, with the run's other settings.
"""

from __future__ import annotations

import dataclasses
import math
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Final

from pipelines.config.entries import ConfigError, Entry, Source, check_key, parse_set
from pipelines.config.schema import SECTION_BY_NAME
from pipelines.experiments.tasks import ENV_SETTINGS
from pipelines.loop.unread import reads_setting, unread_because

if TYPE_CHECKING:
    from pipelines.config import RunConfig
    from pipelines.experiments.cells import Experiment
    from pipelines.experiments.paper import PaperFigures
    from pipelines.experiments.tasks import World
    from pipelines.loop.controllers import ControllerSpec

MAX_VALUES: Final[int] = 12  # each value (each combination) is a whole column of cells per method and size
ENV_SECTIONS: Final[tuple[str, str]] = ("env", "env.orca")  # their keys in ENV_SETTINGS vary every method
SENSOR_RANGE: Final[str] = "simulate.sensor_range"  # every method's view of the humans, as --sensor-range
# The sections whose varied values are the cell's (its robots, humans, simulator, sensor), not a controller's:
# every method gets a column per value, and they are applied last, to every column the others made
CELL_SECTIONS: Final[tuple[str, ...]] = ("scenario", "simulate", *ENV_SECTIONS)


@dataclasses.dataclass(frozen=True)
class Varied:
    """The setting a sweep varies (``section.key``: an [mpc] key, or controller.margins), and its values as
    the MPC takes them (MarginSpecs for the margins), in the order given."""

    section: str
    key: str
    values: tuple[Any, ...]


def varied(cfg: RunConfig) -> tuple[Varied, ...]:
    """[sweep] vary parsed and every value checked: one setting, or several separated by ";" (``--vary``
    given again) for a grid of every combination; () when the run varies nothing."""
    if cfg.sweep.vary is None:
        return ()
    where = cfg.label("sweep", "vary")
    settings = tuple(_one_setting(cfg, where, part.strip()) for part in cfg.sweep.vary.split(";"))
    names = [f"{v.section}.{v.key}" for v in settings]
    twice = next((name for i, name in enumerate(names) if name in names[:i]), None)
    if twice is not None:
        raise ConfigError(f"{where}: {twice} varies twice; give its values once")
    columns = math.prod(len(v.values) for v in settings)
    if columns > MAX_VALUES:
        raise ConfigError(
            f"{where}: {' x '.join(str(len(v.values)) for v in settings)} = {columns} columns per method; at "
            f"most {MAX_VALUES}"
        )
    return settings


def _one_setting(cfg: RunConfig, where: str, text: str) -> Varied:
    """One ``section.key=V1,V2,..`` of [sweep] vary, every value checked."""
    name, _, raw = text.partition("=")
    section, _, key = name.strip().rpartition(".")
    if (section, key) == ("controller", "margins"):
        if cfg.chosen("controller", "margins"):
            raise ConfigError(
                f"{where} and {cfg.label('controller', 'margins')} both set the margins: give them once"
            )
        items = _margin_items(raw)
    elif section == "mpc":
        check_key(f"{where} {text!r}", SECTION_BY_NAME["mpc"], key)
        if key == "jit":
            raise ConfigError(
                f"{where}: a sweep compiles by [sweep] jit (--jit), which leaves the cells alone"
            )
        if cfg.chosen("mpc", key):
            raise ConfigError(f"{where} and {cfg.label('mpc', key)} both set mpc.{key}: give its values once")
        items = [item.strip() for item in raw.split(",")]
    elif (section, key) == ("scenario", "robots"):
        if cfg.chosen("scenario", "robots"):
            raise ConfigError(
                f"{where} and {cfg.label('scenario', 'robots')} both set the robots: give them once"
            )
        items = [item.strip() for item in raw.split(",")]
    elif section in ENV_SECTIONS and env_name(section, key) in ENV_SETTINGS or name.strip() == SENSOR_RANGE:
        if cfg.chosen(section, key):
            raise ConfigError(
                f"{where} and {cfg.label(section, key)} both set {section}.{key}: give its values once"
            )
        items = [item.strip() for item in raw.split(",")]
    else:
        raise ConfigError(
            f"{where} {text!r}: only an [mpc] setting (mpc.KEY=V1,V2,...), the margins (controller.margins="
            "M1,M2,...), the robots (scenario.robots=M1,M2,...), a simulator setting (env.KEY or "
            f"env.orca.KEY, one of {', '.join(ENV_SETTINGS)}) or the sensor range ({SENSOR_RANGE}=R1,R2,...) "
            "vary; the predictors and controllers have experiments of their own (predictors, controllers)"
        )
    if len(items) < 2 or not all(items):
        raise ConfigError(f"{where} {text!r}: expected {section}.{key}=V1,V2,... with at least two values")
    if len(items) > MAX_VALUES:
        raise ConfigError(f"{where}: at most {MAX_VALUES} values, got {len(items)}")
    check = _margins if section == "controller" else _checked
    values = tuple(check(cfg, where, f"{section}.{key}", item) for item in items)
    repeated = next((i for i in range(len(items)) if values[i] in values[:i]), None)
    if repeated is not None:
        first = items[values.index(values[repeated])]
        same = "" if first == items[repeated] else f" ({first} again: both {shown(values[repeated])})"
        raise ConfigError(f"{where}: value {items[repeated]} is given more than once{same}")
    return Varied(section, key, values)


def env_name(section: str, key: str) -> str:
    """The ``World.env_settings`` name of the [env] or [env.orca] ``key``: time_limit, orca.time_horizon."""
    return f"orca.{key}" if section == "env.orca" else key


def _margin_items(raw: str) -> list[str]:
    """The margins of ``M1,M2,..``: fixed margins hold commas themselves (``fixed:0.1,0.1,0.1,0.1``), so a
    bare number continues the fixed margins before it (no margins value is a bare number)."""
    items: list[str] = []
    for token in (t.strip() for t in raw.split(",")):
        if items and items[-1].startswith("fixed:") and _is_number(token):
            items[-1] += "," + token
        else:
            items.append(token)
    return items


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _margins(cfg: RunConfig, where: str, name: str, item: str) -> Any:
    """``item`` as ``--margins`` takes it."""
    from pipelines.errors import PipelineError
    from pipelines.loop.margins import parse_margins

    try:
        return parse_margins(item)
    except PipelineError as exc:
        raise ConfigError(f"{where} value {item}: {exc}") from None


def _checked(cfg: RunConfig, where: str, name: str, item: str) -> Any:
    """``item`` as the run takes ``name`` (``mpc.KEY``, ``scenario.robots``), checked as ``--set
    name=item`` is, with the run's other settings (a d_min below the contact distance, a horizon the
    predictor cannot cover, robots out of range ...)."""
    from pipelines.config.resolve import resolve

    try:
        entry = parse_set(f"{name}={item}")
    except ConfigError as exc:
        raise ConfigError(str(exc).replace(f"--set {name}", f"{where} value {item}")) from None
    if entry.value is None:  # --set's null, which unsets: a column needs a value of its own
        raise ConfigError(f"{where} value {item}: a column needs a value; null unsets only in --set")
    own = [
        Entry(section, key, _as_written(cfg.values[section][key]), source)
        for (section, key), source in cfg.sources.items()
    ]
    probe = resolve([*own, dataclasses.replace(entry, source=Source("cli", f"{where} value {item}"))])
    return probe.values[entry.section][entry.key]


def _as_written(value: Any) -> Any:
    """A resolved value as an entry gives it (lists were made tuples)."""
    return list(value) if isinstance(value, tuple) else value


def shown(value: Any) -> str:
    """A value as a column label shows it: ``0.8``, ``8``, ``standing``, ``true``, margins by their label
    (``cp0.1``); a float as ``config show`` writes it (``1e7``, where ``str`` gave ``10000000.0``: w_coll's
    columns read as counts of zeros)."""
    from pipelines.loop.margins import MarginSpec

    if isinstance(value, MarginSpec):
        return value.label
    if isinstance(value, float):
        from pipelines.config.render import toml_value

        return toml_value(value)
    return str(value).lower() if isinstance(value, bool) else str(value)


def with_values(experiment: Experiment, vary: Varied, table_i: Any, where: str) -> Experiment:
    """A method per value after each method that plans with a predictor (labelled ``CMPC d_min=1.0``,
    ``CMPC margins=cp0.1``, the values in the order given), the others (orca, straight) once; a value that is
    Table I's (``table_i``; margins none) adds nothing to the cell, and its columns keep the paper's
    figures. A number of robots gives every method a column per value (``ORCA robots=6``): the cell the
    sweep's ``--robots`` makes, with the paper's figures only beside its 3 (summary.paper_figures)."""
    key, name = vary.key, experiment.name
    _check_applies(experiment, vary, where)
    simulator = vary.section in ENV_SECTIONS
    sensed = f"{vary.section}.{vary.key}" == SENSOR_RANGE
    if simulator:
        key = env_name(vary.section, key)
    methods: list[tuple[str, ControllerSpec]] = []
    worlds: dict[str, World] = {}
    robots: dict[str, int] = {}
    paper: dict[tuple[str, int], PaperFigures] = {}
    for label, spec in experiment.methods:
        own = dict(spec.mpc_overrides)
        if vary.section == "mpc" and key in own and spec.kind.uses_predictor:
            raise ConfigError(
                f"{where}: method {label!r} of experiment {name!r} sets {key} = {own[key]!r} itself; vary "
                "another setting"
            )
        columns = [(label, spec)]
        if vary.section in CELL_SECTIONS or reads_setting(spec, key):
            columns = [
                (f"{label} {key}={shown(v)}", _with_value(spec, vary, v, table_i)) for v in vary.values
            ]
        base = experiment.method_worlds.get(label, experiment.world)
        for k, (column, column_spec) in enumerate(columns):
            methods.append((column, column_spec))
            world = base.with_env({key: vary.values[k]}) if simulator else base
            world = world.sensing(vary.values[k]) if sensed else world
            if label in experiment.method_worlds or world != base:
                worlds[column] = world
            if vary.section == "scenario":
                robots[column] = vary.values[k]
            elif label in experiment.method_robots:
                robots[column] = experiment.method_robots[label]
            if column_spec == spec and world == base:  # the paper's figures are of Table I's settings
                paper |= {(column, n): fig for (of, n), fig in experiment.paper.items() if of == label}
    title = f"{experiment.title}; {key} = {', '.join(shown(v) for v in vary.values)}"
    return dataclasses.replace(
        experiment,
        title=title,
        methods=tuple(methods),
        method_worlds=MappingProxyType(worlds),
        method_robots=MappingProxyType(robots),
        paper=MappingProxyType(paper),
    )


def _with_value(spec: ControllerSpec, vary: Varied, value: Any, table_i: Any) -> ControllerSpec:
    """``spec`` with the varied setting at ``value``: Table I's adds no override to the cell, and the
    number of robots and the simulator's settings are the cell's, not the controller's."""
    if vary.section in CELL_SECTIONS:
        return spec
    if vary.section == "controller":
        return dataclasses.replace(spec, margins=value)
    extra = () if value == table_i else ((vary.key, value),)
    return dataclasses.replace(spec, mpc_overrides=(*spec.mpc_overrides, *extra))


def _check_applies(experiment: Experiment, vary: Varied, where: str) -> None:
    """Refuse a variation no method would run, or one that undoes what the experiment compares."""
    key, name = vary.key, experiment.name
    labels = ", ".join(repr(label) for label, _ in experiment.methods)
    if f"{vary.section}.{key}" == SENSOR_RANGE and any(
        own.sensor_range != experiment.world.sensor_range for own in experiment.method_worlds.values()
    ):
        raise ConfigError(
            f"{where}: experiment {name!r} compares sensor ranges across its methods; they do not vary"
        )
    if vary.section in CELL_SECTIONS:  # every controller drives robots among the humans
        return
    if not any(spec.kind.uses_predictor for _, spec in experiment.methods):
        raise ConfigError(
            f"{where}: the methods of experiment {name!r} ({labels}) plan with no predictor; "
            f"[{vary.section}] {key} applies to the controllers that do"
        )
    if vary.section == "mpc" and not any(reads_setting(spec, key) for _, spec in experiment.methods):
        why = dict.fromkeys(unread_because(spec, key) for _, spec in experiment.methods)
        raise ConfigError(f"{where}: the methods of experiment {name!r} {' or '.join(map(str, why))}")
    if vary.section == "controller" and not experiment.margins_swappable:
        raise ConfigError(f"{where}: experiment {name!r} fixes each method's margins; they do not vary")
    if key == "w_floc" and 0 in vary.values and len({spec.flocking for _, spec in experiment.methods}) > 1:
        raise ConfigError(
            f"{where}: experiment {name!r} compares flocking on and off; w_floc = 0 turns it off in all its "
            "methods"
        )
