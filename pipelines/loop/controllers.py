"""The junction between the simulator and the robot controllers: what a controller is to the closed loop.

``crowdsim`` never imports ``mpc``; this module names the controller protocol and holds the explicit, typed
registry of controllers: the baselines (``pipelines.loop.baselines`` adapts ``crowdsim.baselines``) and the
game-theoretic MPCs (``pipelines.loop.mpc``), plus the plugins (entry points in the group
``crowdmpc.controllers``, ``crowdmpc --plugin module:Class``; ``pipelines.loop.spec`` says how they are
found). What the pipelines must know before a controller exists (does it plan with a predictor, can its NLPs
be compiled) is stated per name in ``pipelines.loop.spec``; each controller states the rest itself
(``predictor``, ``describe``, ``close``). Builders import lazily so that choosing ``orca`` never loads CasADi
solvers.

A plugin is a class implementing ``Controller``, built as ``Class(spec, env_config, jit=jit)``: ``spec`` the
``ControllerSpec`` (its ``predictor``, ``mpc_overrides`` ... for the plugin to use as it sees fit),
``env_config`` the simulator's ``EnvConfig`` (None: the defaults), ``jit`` whether the run asks for compiled
NLPs. Optional class attributes ``uses_predictor`` and ``compiles`` (bools) state its facts.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final, Protocol

from crowdsim.control import ControlOutput
from crowdsim.env_config import EnvConfig
from pipelines.errors import PipelineError
from pipelines.loop.spec import (
    CONTROLLER_KINDS,
    CONTROLLER_METHODS,
    COUPLINGS,
    ControllerKind,
    ControllerName,
    ControllerPlugin,
    ControllerSpec,
    Coupling,
    UnknownController,
    controller_names,
    controller_plugin,
    is_plugin_spec,
    is_shipped,
    load_controller_plugin,
    register_controller_plugins,
)
from predictors.errors import short_repr

if TYPE_CHECKING:
    from types import EllipsisType

    from crowdsim.env import Observation
    from pipelines.loop.margins_read import Planned, Refused
    from predictors.base import Predictor
    from predictors.zoo import Located as ZooLocated

# The spec and the controllers' facts live in pipelines.loop.spec (the MPC adapter needs them, and the
# registry needs the adapter); they are re-exported here, the registry's public face.
__all__ = [
    "CONTROLLERS",
    "CONTROLLER_KINDS",
    "COUPLINGS",
    "ControlOutput",
    "Controller",
    "ControllerKind",
    "ControllerName",
    "ControllerSpec",
    "ControllerPlugin",
    "ControllerReads",
    "Coupling",
    "UnknownController",
    "controller_name",
    "controller_names",
    "load_controller_plugin",
    "make_controller",
    "register_controller_plugins",
]


class Controller(Protocol):
    """A robot controller in the closed loop; it owns its failures (a step that cannot be solved falls back
    inside the controller and says so in ``ControlOutput.fallback``)."""

    name: str
    predictor: str | None  # the pedestrian predictor it plans with, None for a controller that uses none

    def reset(self, obs: Observation) -> None:
        """Start a new episode (problem sizes are known from ``obs``)."""
        ...

    def act(self, obs: Observation) -> ControlOutput: ...

    def describe(self) -> dict[str, Any]:
        """What the episode metadata records about this controller: ``predictor_sha256`` and ``config``."""
        ...

    def close(self) -> None:
        """Release what it holds (solver threads); it may still be used after."""
        ...


@dataclass(frozen=True)
class ControllerReads:
    """What a shipped MPC reads of the zoo as it is built, read already by the command that builds it
    (simulate, whose notes describe them): read again, a `zoo add --replace` or a calibrate run between the
    reads had the notes describe other weights or another block than the controller planned with. A
    plugin loads its own predictor, of the entry located already (``located``), and its lookups of its
    spec's margins, as it is built, find the block of ``calibration`` (pipelines.loop.margins_handed)."""

    # the one spec.predictor names; None: loaded as the MPC is built; Refused: its load refused, raised there
    predictor: Predictor | Refused | None = None
    calibration: Planned | EllipsisType = ...  # margins_read.look_up of its weights; ...: read then
    # the zoo entry spec.predictor names, as the command located it (None: none; ...: not located), which a
    # plugin that loads the run's predictor itself loads (predictors.registry.handing)
    located: ZooLocated | None | EllipsisType = ...


# (spec, env_config, jit, what the command read for it) -> controller
Builder = Callable[[ControllerSpec, "EnvConfig | None", bool, ControllerReads], Controller]


def _straight(
    spec: ControllerSpec, env_config: EnvConfig | None, jit: bool, _: ControllerReads
) -> Controller:
    from pipelines.loop.baselines import straight

    return straight(env_config)


def _orca(spec: ControllerSpec, env_config: EnvConfig | None, jit: bool, _: ControllerReads) -> Controller:
    from pipelines.loop.baselines import orca

    return orca(env_config)


def _cmpc(spec: ControllerSpec, env_config: EnvConfig | None, jit: bool, read: ControllerReads) -> Controller:
    from pipelines.loop.mpc import MPCController

    return MPCController(
        spec, False, env_config=env_config, jit=jit, predictor=read.predictor, calibration=read.calibration
    )


def _dmpc(spec: ControllerSpec, env_config: EnvConfig | None, jit: bool, read: ControllerReads) -> Controller:
    from pipelines.loop.mpc import MPCController

    return MPCController(
        spec, True, env_config=env_config, jit=jit, predictor=read.predictor, calibration=read.calibration
    )


CONTROLLERS: Final[Mapping[ControllerName, Builder]] = {
    "straight": _straight,
    "orca": _orca,
    "cmpc": _cmpc,
    "dmpc": _dmpc,
}


def make_controller(
    spec: ControllerSpec,
    env_config: EnvConfig | None = None,
    *,
    jit: bool = False,
    read: ControllerReads | None = None,
) -> Controller:
    """The controller of ``spec`` for episodes simulated under ``env_config`` (a predictor that observes the
    simulator, the ORCA oracle, simulates the humans with it; None: the default conventions). ``jit``
    compiles the NLPs of a controller whose kind ``compiles`` and is ignored by the others. ``read``: what
    the command read of the zoo for it already (``ControllerReads``; None: the controller reads it)."""

    # a name or a dict given in their place failed on an attribute deep inside (no attribute 'controller')
    if not isinstance(spec, ControllerSpec):
        raise PipelineError(
            f"make_controller takes a ControllerSpec (ControllerSpec('cmpc')), got {short_repr(spec)}"
        )
    if not (env_config is None or isinstance(env_config, EnvConfig)):
        raise PipelineError(
            f"make_controller: env_config must be an EnvConfig or None, got {short_repr(env_config)}"
        )
    if not (read is None or isinstance(read, ControllerReads)):
        raise PipelineError(
            f"make_controller: read must be a ControllerReads or None, got {short_repr(read)}"
        )
    if is_shipped(spec.controller):
        controller_names()  # PipelineError when an installed entry point takes its name
        return CONTROLLERS[spec.controller](spec, env_config, jit, read or ControllerReads())
    return _build_plugin(controller_plugin(spec.controller), spec, env_config, jit, read or ControllerReads())


def _build_plugin(
    plugin: ControllerPlugin,
    spec: ControllerSpec,
    env_config: EnvConfig | None,
    jit: bool,
    read: ControllerReads,
) -> Controller:
    """``plugin.cls(spec, env_config, jit=jit)``; a constructor that fails, or builds something without a
    ``name`` and a ``predictor``, or whose ``predictor`` is not the one the run's records and cell keys name
    (``spec.predictor`` for a plugin with ``uses_predictor``, else None), is a one-line PipelineError naming
    the plugin. An unknown ``spec.predictor`` is refused first for a plugin with ``uses_predictor``, as the
    shipped MPCs refuse it when they load it (``UnknownPredictor``); one whose zoo entry the command located
    (``read.located``) is known, and the plugin's ``load_predictor`` of it loads that entry; its lookups
    of ``spec.margins`` find the block ``read.calibration`` holds (``handing_calibration``)."""
    from pipelines.loop.margins_handed import handing_calibration
    from predictors.registry import handing

    located = read.located if read.located is not ... and read.located is not None else None
    located = located if located is not None and located.entry.name == spec.predictor else None
    if plugin.kind.uses_predictor and located is None:
        from predictors.errors import UnknownPredictor
        from predictors.registry import available

        names = available()  # every name load_predictor accepts
        if spec.predictor not in names:
            raise UnknownPredictor(spec.predictor, names)
    # the block of a lookup that found one (not a refusal, nor None: no block needed) for the plugin's own
    at = read.calibration if isinstance(read.calibration, tuple) else None
    try:
        with handing(located), handing_calibration(spec.margins, spec.predictor_name, at):
            controller = plugin.cls(spec, env_config, jit=jit)
    except PipelineError:
        raise
    except Exception as exc:  # the plugin's own validation (TypeError, ValueError, an assert ...)
        raise PipelineError(
            f"controller {plugin.name!r}: building it failed: {type(exc).__name__}: {exc}"
        ) from None
    name, predictor = getattr(controller, "name", None), getattr(controller, "predictor", ())
    if not _names_itself(name, predictor):
        raise PipelineError(
            f"controller {plugin.name!r}: a {plugin.cls.__name__} needs a non-empty str name and a predictor "
            f"(str or None), got name={name!r:.60}, predictor={predictor!r:.60}"
        )
    if is_shipped(name):  # recorded as "cmpc", its episodes read as CMPC's in compare and review
        raise PipelineError(
            f"controller {plugin.name!r}: its name {name!r} is a shipped controller's, under which its "
            "records would read as that one's: give the class a name of its own"
        )
    if plugin.kind.uses_predictor and predictor != spec.predictor:
        raise PipelineError(
            f"controller {plugin.name!r}: a {plugin.cls.__name__} has uses_predictor = True: its predictor "
            f"must be spec.predictor {spec.predictor!r:.60}, got {predictor!r:.60}"
        )
    if not plugin.kind.uses_predictor and predictor is not None:
        raise PipelineError(
            f"controller {plugin.name!r}: a {plugin.cls.__name__} has uses_predictor = False: its predictor "
            f"must be None, got {predictor!r:.60} (uses_predictor = True plans with spec.predictor)"
        )
    return controller  # type: ignore[no-any-return]


def controller_name(value: str) -> str:
    """``--controller``'s type: ``value`` if some source registers it, else the parser's one-line error
    (argparse's own wording for an unknown name; how to register it for a ``module:Class``)."""
    try:
        names = controller_names()
    except PipelineError as exc:  # an installed entry point that takes a shipped controller's name
        raise argparse.ArgumentTypeError(str(exc)) from None
    if value in names:
        return value
    if is_plugin_spec(value):
        raise argparse.ArgumentTypeError(str(UnknownController(value, [])))
    choices = ", ".join(repr(name) for name in names)
    raise argparse.ArgumentTypeError(f"invalid choice: {value!r:.60} (choose from {choices})")


def check_controller(controller: object, where: str = "run_episode") -> None:
    """PipelineError unless ``controller`` has the protocol's methods (a spec or a name given in its place,
    in a notebook, failed on an attribute deep inside), its ``name`` a non-empty str and its ``predictor`` a
    str or None; ``where``: the function it was given to (run_episode, run_gym_episode, RangeLimited)."""
    if isinstance(controller, ControllerSpec):
        takes_spec = " (run_episodes takes the spec)" if where == "run_episode" else ""
        raise PipelineError(
            f"{where} takes a controller built by make_controller(spec), not the ControllerSpec{takes_spec}"
        )
    missing = [m for m in (*CONTROLLER_METHODS, "name", "predictor") if not hasattr(controller, m)]
    if missing:
        raise PipelineError(
            f"{where}: {short_repr(controller)} is no controller: it has no {', '.join(missing)} "
            "(build one with make_controller(ControllerSpec(...)))"
        )
    # what the records and recordings write as "controller" and "predictor" (strings by their schemas): a
    # hand-built controller's name=5 wrote an /episode/metrics message that review --check refused
    name, predictor = controller.name, controller.predictor  # type: ignore[attr-defined]
    if not _names_itself(name, predictor):
        raise PipelineError(
            f"{where}: a controller needs a non-empty str name and a predictor (str or None), got "
            f"name={short_repr(name)}, predictor={short_repr(predictor)}"
        )


def _names_itself(name: object, predictor: object) -> bool:
    """Whether a controller's ``name`` is a non-empty str and its ``predictor`` a str or None: what records
    and recordings store as "controller" and "predictor"."""
    return isinstance(name, str) and bool(name) and (predictor is None or isinstance(predictor, str))


WORLD_UNITS: Final[dict[str, str]] = {
    "dt": "s",
    "obs_len": "steps",
    "radius": "m",
    "v_pref": "m/s",
    "v_max": "m/s",
    "a_max": "m/s^2",
}


def check_built_for(controller: object, env_config: EnvConfig, where: str) -> None:
    """PipelineError when ``controller`` was built for a simulator of other world facts than ``env_config``,
    or, moving by ORCA, of other ORCA settings (``ORCA_SETTINGS``) (the shipped controllers keep theirs as
    ``env_config``; a plugin without one is not checked). Built by
    ``make_controller(spec)`` for the default world and run in a slower or larger-bodied one, an MPC planned
    at the default speed (the simulator clipping every plan) and with a d_min checked against the default
    radius, silently; only another tau was refused, at reset."""
    built = getattr(controller, "env_config", None)
    if not isinstance(built, EnvConfig):
        return
    there, here = built.world(), env_config.world()
    differ = [
        f"{name} {getattr(there, name):g} {unit} there, {getattr(here, name):g} here"
        for name, unit in WORLD_UNITS.items()
        if getattr(there, name) != getattr(here, name)
    ]
    if differ:
        raise PipelineError(
            f"{where}: the controller {controller_label(controller)} was built for another world "
            f"({'; '.join(differ)}): build it with make_controller(spec, env_config) for this simulator"
        )
    _check_orca_built_for(controller, built, env_config, where)


# What a shipped controller moves by ORCA with, as the simulator it was built for sets it: the ORCA oracle its
# predicted humans (predictors.oracle: seeing the robots or not), the ORCA baseline its robots. Built for the
# default simulator and run among humans blind to the robots, the oracle predicted them dodging (0.12 m off
# a step ahead, where it is exact), silently. (The oracle by its name: predictors.oracle imports CasADi.)
ORCA_SETTINGS: Final[dict[str, tuple[str, ...]]] = {
    "orca_oracle": ("robots_visible", "orca", "orca_radius_margin"),
    "orca": ("orca", "orca_radius_margin"),
}


def _check_orca_built_for(controller: object, built: EnvConfig, env_config: EnvConfig, where: str) -> None:
    """``check_built_for``'s ORCA settings (``ORCA_SETTINGS``) of a controller planning with the oracle or
    driving by ORCA."""
    predictor, name = getattr(controller, "predictor", None), getattr(controller, "name", None)
    read = ORCA_SETTINGS.get(predictor if predictor == "orca_oracle" else str(name), ())
    differ = [
        f"{key} {getattr(built, key)} there, {getattr(env_config, key)} here"
        for key in read
        if getattr(built, key) != getattr(env_config, key)
    ]
    if differ:
        raise PipelineError(
            f"{where}: the controller {controller_label(controller)} moves by the ORCA settings of the "
            f"simulator it was built for ({'; '.join(differ)}): build it with make_controller(spec, "
            "env_config) for this simulator"
        )


def controller_label(controller: object) -> str:
    return repr(getattr(controller, "name", type(controller).__name__))
