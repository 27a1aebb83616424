"""What a sweep will run, settled before any worker starts: the experiment with the config's choices applied
to every method (``configured_experiment``), refusing in one line the world settings a sweep cannot honour
(``check_world``); the checks of the plan itself are pipelines.commands.sweep_checks."""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import replace
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Final

from pipelines.errors import PipelineError

if TYPE_CHECKING:
    from pipelines.config import RunConfig
    from pipelines.experiments.cells import Experiment
    from pipelines.loop.margins import MarginSpec
    from pipelines.loop.spec import ControllerSpec


def configured_experiment(cfg: RunConfig, *, run: bool = False) -> Experiment:
    """The experiment of ``cfg`` with its choices applied to every method: the predictors, predictor and
    margins (--predictors, --predictor, --margins or the config), the profile and visibility, and the
    [controller] and [mpc] values that differ from their defaults (a value the experiment compares across
    its methods is refused). For a sweep to ``run`` (its dry run too, not a report), the choices the command
    line made that no cell would read are refused too (``idle_choices.check_sweep_choices``)."""
    from pipelines.experiments.cells import get_experiment
    from pipelines.experiments.tasks import World
    from pipelines.loop.margins import parse_margins

    experiment = get_experiment(cfg.sweep.experiment or "")
    if cfg.sweep.predictors is not None:
        experiment = _applied(cfg, "sweep", "predictors", experiment.with_predictors, cfg.sweep.predictors)
    elif experiment.predictor_list:
        from pipelines.experiments.methods import swap_predictors
        from predictors.registry import available

        experiment = experiment.with_predictors(swap_predictors(available()))
    if cfg.sweep.controllers is not None:
        experiment = _applied(cfg, "sweep", "controllers", experiment.with_controllers, cfg.sweep.controllers)
    if cfg.controller.predictor:
        experiment = _applied(
            cfg, "controller", "predictor", experiment.with_predictor, cfg.controller.predictor
        )
    if cfg.controller.margins:
        margins = parse_margins(cfg.controller.margins)
        experiment = _applied(cfg, "controller", "margins", experiment.with_margins, margins)
        _check_margins_apply(cfg, experiment, margins)
    if cfg.chosen("env", "profile") or cfg.chosen("env", "robots_visible"):
        world = World(
            cfg.env.profile if cfg.chosen("env", "profile") else experiment.world.profile,
            ("visible" if cfg.env.robots_visible else "invisible")
            if cfg.chosen("env", "robots_visible")
            else experiment.world.visibility,
        )
        key = "profile" if cfg.chosen("env", "profile") else "robots_visible"
        experiment = _applied(cfg, "env", key, experiment.with_world, world)
    if cfg.chosen("simulate", "sensor_range") or cfg.chosen("simulate", "sensor_tracks"):
        experiment = _with_sensing(cfg, experiment)
    if cfg.env.crowd != "orca":
        experiment = _with_crowd(experiment, cfg.env.crowd)
    settings = env_settings(cfg)
    if settings:
        experiment = experiment.with_env(settings)
    for key in ("controller", "coupling", "flocking", "record_iterations"):
        if cfg.chosen("controller", key):
            experiment = _with_spec_field(cfg, experiment, key, getattr(cfg.controller, key))
    experiment = _with_mpc_settings(cfg, experiment)
    if run:
        from pipelines.commands.idle_choices import check_sweep_choices

        check_sweep_choices(cfg, experiment)
    return experiment


def _with_mpc_settings(cfg: RunConfig, experiment: Experiment) -> Experiment:
    """The [mpc] values that differ from Table I, and the varied ones (--vary) each in its place among them:
    the overrides of a cell stay in the [mpc] table's order, so that a varied value's cell is the one
    ``--set`` makes (the same key, the same episodes); varied margins first, as they have no place there,
    and varied robots last, as they are no controller's."""
    from pipelines.commands.sweep_vary import CELL_SECTIONS, varied, with_values

    where = cfg.label("sweep", "vary")
    settings = varied(cfg)
    for vary in settings:
        if vary.section == "controller":
            experiment = with_values(experiment, vary, None, where)
    order = list(cfg.values["mpc"])
    pending = sorted((v for v in settings if v.section == "mpc"), key=lambda v: order.index(v.key))
    for key, value in cfg.mpc_overrides():
        while pending and order.index(pending[0].key) < order.index(key):
            vary = pending.pop(0)
            experiment = with_values(experiment, vary, cfg.default("mpc", vary.key), where)
        experiment = _with_mpc_override(cfg, experiment, key, value)
    for vary in pending:
        experiment = with_values(experiment, vary, cfg.default("mpc", vary.key), where)
    for vary in settings:  # last: every column the others made, at each simulator value, number of robots
        if vary.section in CELL_SECTIONS:
            experiment = with_values(experiment, vary, None, where)
    return experiment


def _check_margins_apply(cfg: RunConfig, experiment: Experiment, margins: MarginSpec) -> None:
    """Refuse margins that no method plans with (Experiment.with_margins gives them to the methods that
    predict the humans), rather than run a sweep that ignores them."""
    from pipelines.loop.spec import CONTROLLER_KINDS

    if margins.mode == "none" or any(spec.margins == margins for _, spec in experiment.methods):
        return
    labels = ", ".join(repr(label) for label, _ in experiment.methods)
    methods = f"method {labels} plans" if len(experiment.methods) == 1 else f"methods {labels} plan"
    predicting = ", ".join(name for name, kind in CONTROLLER_KINDS.items() if kind.uses_predictor)
    option = f"{cfg.label('controller', 'margins')} {cfg.controller.margins}"
    raise PipelineError(
        f"{option}: {methods} with no predictor; margins apply to the controllers that do ({predicting}, "
        "or a plugin with uses_predictor = True)"
    )


def _applied(
    cfg: RunConfig, section: str, key: str, method: Callable[[Any], Experiment], value: Any
) -> Experiment:
    """``method(value)``, its refusal named by where the value came from when that is no option (the
    experiment's message names the option: "--predictors applies only to ...", said of ``--set
    sweep.predictors``, named an option not given)."""
    try:
        return method(value)
    except PipelineError as exc:
        source = cfg.source(section, key)
        if source is None or source.kind == "cli":
            raise
        message = str(exc)
        for option, words in _OPTION_WORDS.items():
            message = re.sub(rf"{re.escape(option)}\b(?!-)", words, message)
        raise cfg.error(section, key, message) from None


# The options an experiment's refusal names, as a config file or --set names the same values.
_OPTION_WORDS: Final[Mapping[str, str]] = {
    "--profile and --visibility": "[env] profile and robots_visible",
    "--predictors": "[sweep] predictors",
    "--controllers": "[sweep] controllers",
    "--predictor": "[controller] predictor",
    "--margins": "[controller] margins",
    "--sensor-range and --no-sensor-tracks": "[simulate] sensor_range and sensor_tracks",
}


def _with_spec_field(cfg: RunConfig, experiment: Experiment, key: str, value: Any) -> Experiment:
    """Every method's ``ControllerSpec.<key>`` set to ``value`` (but the controller kind, only the methods
    that plan with a predictor: ``_planning``), unless the experiment compares it."""
    import dataclasses

    applies = _planning(cfg, experiment, "controller", key) if key != "controller" else experiment.methods
    own = {getattr(spec, key) for _, spec in applies}
    if len(own) > 1:
        raise cfg.error(
            "controller",
            key,
            f"experiment {experiment.name!r} compares its methods' {key} ({sorted(map(str, own))}); "
            "leave it unset for this sweep",
        )
    methods = tuple(
        (label, dataclasses.replace(spec, **{key: value}) if (label, spec) in applies else spec)
        for label, spec in experiment.methods
    )
    return dataclasses.replace(experiment, methods=methods)


def _planning(
    cfg: RunConfig, experiment: Experiment, section: str, key: str
) -> tuple[tuple[str, ControllerSpec], ...]:
    """The methods a [controller] or [mpc] value applies to: those that plan with a predictor (ORCA and the
    straight line have no MPC, and their cell keys took --set mpc.horizon=8 while they ran as before); a
    value none of them would read is refused, as margins are (``_check_margins_apply``)."""
    from pipelines.loop.spec import CONTROLLER_KINDS

    planning = tuple((label, spec) for label, spec in experiment.methods if spec.kind.uses_predictor)
    if not planning:
        labels = ", ".join(repr(label) for label, _ in experiment.methods)
        predicting = ", ".join(name for name, kind in CONTROLLER_KINDS.items() if kind.uses_predictor)
        raise cfg.error(
            section,
            key,
            f"the methods of experiment {experiment.name!r} ({labels}) plan with no predictor; [{section}] "
            f"{key} applies to the controllers that do ({predicting})",
        )
    return planning


def _with_mpc_override(cfg: RunConfig, experiment: Experiment, key: str, value: Any) -> Experiment:
    """Every method's MPC with ``key = value`` (ControllerSpec.mpc_overrides, part of the cell keys), unless
    a method sets that key itself; a key of the flocking term only in the methods that flock."""
    import dataclasses

    from pipelines.loop.unread import reads_setting, unread_because

    if key == "jit":
        raise cfg.error(
            "mpc", key, "a sweep compiles by [sweep] jit (--jit auto|on|off), which leaves the cells alone"
        )
    if key == "w_floc" and value == 0 and len({spec.flocking for _, spec in experiment.methods}) > 1:
        # w_floc = 0 is flocking off in every method: the comparison would be NF against NF.
        raise cfg.error(
            "mpc",
            key,
            f"experiment {experiment.name!r} compares flocking on and off; w_floc = 0 turns it off in all "
            "its methods",
        )
    applies = _planning(cfg, experiment, "mpc", key)
    source = cfg.source("mpc", key)
    # a file's value is judged by the controller alone: the cells of a folder swept with it keep their keys
    given = source is None or source.kind != "file"
    applies = tuple((label, spec) for label, spec in applies if reads_setting(spec, key, by_values=given))
    if not applies and not given:
        return experiment  # a file may serve other experiments too (safe_crossing.toml's DMPC settings)
    if not applies:  # they all plan (_planning refuses otherwise), none reads the key
        why = dict.fromkeys(unread_because(spec, key) for _, spec in experiment.methods)
        raise cfg.error(
            "mpc", key, f"the methods of experiment {experiment.name!r} {' or '.join(map(str, why))}"
        )
    methods = []
    for label, spec in experiment.methods:
        if (label, spec) not in applies:
            methods.append((label, spec))
            continue
        own = dict(spec.mpc_overrides)
        if key in own and own[key] != value:
            raise cfg.error(
                "mpc",
                key,
                f"method {label!r} of experiment {experiment.name!r} sets {key} = {own[key]!r} itself; "
                "leave it unset for this sweep",
            )
        overrides = spec.mpc_overrides if key in own else (*spec.mpc_overrides, (key, value))
        methods.append((label, dataclasses.replace(spec, mpc_overrides=overrides)))
    return dataclasses.replace(experiment, methods=tuple(methods))


def check_world(cfg: RunConfig) -> None:
    """A sweep's cells share Table I's world facts: refuse the [world] values the run asks for (``_asked``),
    [scenario] humans and name (``_check_scenario``), rather than ignore them. ([env] and [env.orca] apply
    to every cell: ``env_settings``.)"""
    from pipelines.commands.simulate_checks import check_recording

    _check_scenario(cfg)
    _check_simulate(cfg)
    check_recording(cfg)
    why = (
        "a sweep's cells share Table I's world facts (time step, history, radius, bounds), which the "
        "controllers and predictors are built for; [world] values apply to simulate only"
    )
    for key in cfg.values["world"]:
        if _asked(cfg, "world", key, cfg.default("world", key)):
            raise cfg.error("world", key, f"{cfg.values['world'][key]!r}: {why}")


def check_iterations_recorded(cfg: RunConfig) -> None:
    """Refuse ``record_iterations`` with nothing recorded, as simulate does: of a sweep about to run, not of
    one reported (``--report-only``), whose recorded config the older code ran as it was."""
    if cfg.controller.record_iterations and cfg.sweep.record == "none":  # as simulate refuses it
        raise cfg.error(
            "controller",
            "record_iterations",
            "the iterations are written to the MCAP recordings; give --record failures or all too (or "
            "[sweep] record)",
        )


def env_settings(cfg: RunConfig) -> dict[str, Any]:
    """The [env] and [env.orca] values the run asks for (``_asked``) beside the profile, visibility and
    crowd, by ``World.env_settings``' keys ("orca." for [env.orca]): every cell runs with them, its key
    naming them."""
    from crowdsim.profiles import PROFILES
    from pipelines.config.schema import ENV_PROFILE_KEYS

    profile = PROFILES[cfg.env.profile]
    asked = {}
    for section, key, default in (
        *(("env.orca", k, cfg.default("env.orca", k)) for k in cfg.values["env.orca"]),
        *(
            # a profile's convention is asked for whatever its value: `config show` leaves it unset
            ("env", k, _ANY if k in ENV_PROFILE_KEYS else getattr(profile, k))
            for k in cfg.values["env"]
            if k not in ("profile", "robots_visible", "crowd")
        ),
    ):
        if _asked(cfg, section, key, default):
            asked[("orca." if section == "env.orca" else "") + key] = cfg.values[section][key]
    return asked


# The default of a value asked for whenever it is set (``_asked``).
_ANY: Final = object()


def _asked(cfg: RunConfig, section: str, key: str, default: Any) -> bool:
    """Whether the run asks for this value, as ``RunConfig.chosen`` tells it but against ``default`` (an
    [env] value's is the config's profile's; ``_ANY``: set at all): given as an option or ``--set``, the
    default too, since an experiment's cells may run another profile (conventions' v1 cells kept v1's 30 s
    limit under ``--set env.time_limit=40.0``, the paper's), or set in a file to another value than the
    default."""
    source, value = cfg.sources.get((section, key)), cfg.values[section][key]
    if source is None or value is None:
        return False
    return source.kind != "file" or default is _ANY or value != default


# What sets, in a sweep, what a [scenario] key sets in simulate.
SWEEP_SCENARIO: dict[str, str] = {
    "humans": "a sweep's crowd sizes are --humans ([sweep] humans)",
    "name": "a sweep's episodes alternate the circle (even episodes) and perpendicular (odd) scenarios",
}


# [simulate] keys a sweep has its own of (sensor_range and sensor_tracks it takes: every method behind them)
SWEEP_OWN: dict[str, str] = {
    "episodes": "a sweep's are --episodes-per-cell ([sweep] episodes_per_cell)",
    "seed": "a sweep's are --seed ([sweep] seed)",
    "record": "a sweep's are --record none|failures|all ([sweep] record), into --out",
    "json": "a sweep writes its records and table into --out",
    "plot": "a sweep draws its plots into --out",
    "progress": "a sweep's is --no-progress",
}


def _check_simulate(cfg: RunConfig) -> None:
    """Refuse a [simulate] value given with --set that a sweep does not read (``--set simulate.seed=7`` ran
    seed 0 without a word); a config file's pass, as a file may serve simulate too."""
    for key, why in SWEEP_OWN.items():
        source = cfg.source("simulate", key)
        if source is not None and source.kind != "file":
            value = cfg.values["simulate"][key]
            raise cfg.error("simulate", key, f"{value!r}: [simulate] {key} applies to simulate only; {why}")


def _check_scenario(cfg: RunConfig) -> None:
    """Refuse a [scenario] value the sweep would not read (all but robots), chosen as ``RunConfig.chosen``
    says: given on the command line, the default too, or set in a file to another value."""
    for key in cfg.values["scenario"]:
        if key != "robots" and cfg.chosen("scenario", key):
            sweep = SWEEP_SCENARIO.get(key, "a sweep plans its own scenarios")
            value = cfg.values["scenario"][key]
            raise cfg.error("scenario", key, f"{value!r}: [scenario] {key} applies to simulate only; {sweep}")


def _with_crowd(experiment: Experiment, crowd: str) -> Experiment:
    """Every cell among the humans of ``crowd`` (--crowd): a BIWI sequence replayed (crowdsim.replay); the
    cells' keys name it, so they never mix with ORCA's."""
    from crowdsim.replay import REACTIVE_SUFFIX

    worlds = {label: replace(own, crowd=crowd) for label, own in experiment.method_worlds.items()}
    recorded = crowd.removesuffix(REACTIVE_SUFFIX)
    title = f"{experiment.title}; among the {recorded.upper()} pedestrians replayed"
    title += ", yielding to the robots" if crowd.endswith(REACTIVE_SUFFIX) else ""
    if any(spec.predictor == "orca_oracle" for _, spec in experiment.methods):
        title += " (where orca_oracle is no oracle: it predicts ORCA humans)"
    return replace(
        experiment,
        title=title,
        world=replace(experiment.world, crowd=crowd),
        method_worlds=MappingProxyType(worlds),
    )


def _with_sensing(cfg: RunConfig, experiment: Experiment) -> Experiment:
    """Every method behind the sensor of [simulate] sensor_range (--sensor-range), as simulate runs it."""
    sensed = cfg.simulate.sensor_range
    if sensed is None:
        if cfg.simulate.sensor_tracks:  # the default, given: nothing to apply
            return experiment
        raise cfg.error(
            "simulate",
            "sensor_tracks",
            "track lengths are a sensor's; give --sensor-range M too (or [simulate] sensor_range)",
        )
    key = "sensor_range" if cfg.chosen("simulate", "sensor_range") else "sensor_tracks"
    return _applied(
        cfg, "simulate", key, lambda r: experiment.with_sensing(r, cfg.simulate.sensor_tracks), sensed
    )
