"""What the user chooses: the controller spec, its option types, and each controller's standing facts.

The facts are what the pipelines need before a controller is built: whether it plans with a predictor (its
records and cell keys then name one) and whether its NLPs can be compiled. The builders that turn a spec
into a controller are the registry of ``pipelines.loop.controllers``, which checks it covers these names.

Controllers come from three sources, in this order, as predictor nets do (``predictors.models``):

* the shipped ones (``CONTROLLER_KINDS``);
* installed packages' entry points in the group ``crowdmpc.controllers`` (``name = "module:Class"``);
* ``module:Class`` given by the user: ``crowdmpc --plugin module:Class`` (``pipelines.plugins``), or the
  ``CROWDMPC_CONTROLLERS`` environment variable (comma-separated), which ``--plugin`` sets so that the
  processes a command starts load it too. The controller's name is then ``module:Class``.

A plugin is a class that implements the ``Controller`` protocol (``pipelines.loop.controllers``: ``name``,
``predictor``, ``reset``, ``act``, ``describe``, ``close``), is built as ``Class(spec, env_config, jit=jit)``
and states its facts as class attributes ``uses_predictor`` and ``compiles`` (bools; False when absent).
Its facts are known once its class is loaded, so they live here with the shipped ones.
"""

from __future__ import annotations

import inspect
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from importlib import metadata
from typing import Any, Final, Literal, TypeGuard, get_args

from pipelines.errors import PipelineError
from pipelines.loop.margins import MarginSpec

# The shipped controllers. Literal rather than Enum: the values travel unchanged through argparse, JSON
# records and MCAP metadata. A plugin's name is any other registered string.
ControllerName = Literal["straight", "orca", "cmpc", "dmpc"]
# "ibr": Algorithm 1/2; "nlp": the predictor inside the joint NLP; "none": predict, then plan (the predictor
# never sees the robots, so its predictions do not answer their plans: the ablation of the paper's coupling)
Coupling = Literal["ibr", "nlp", "none"]
COUPLINGS: Final[tuple[Coupling, ...]] = get_args(Coupling)


@dataclass(frozen=True)
class ControllerKind:
    """A controller's standing facts."""

    uses_predictor: bool  # plans with spec.predictor (records and cell keys name it)
    compiles: bool  # jit=True compiles its NLPs to C (MPCConfig.jit); it changes speed, not results


CONTROLLER_KINDS: Final[Mapping[ControllerName, ControllerKind]] = {
    "straight": ControllerKind(uses_predictor=False, compiles=False),
    "orca": ControllerKind(uses_predictor=False, compiles=False),
    "cmpc": ControllerKind(uses_predictor=True, compiles=True),
    "dmpc": ControllerKind(uses_predictor=True, compiles=True),
}
# The shipped MPCs: the controllers that read flocking, record_iterations and [mpc] (a plugin reads the spec
# as it sees fit).
MPC_CONTROLLERS: Final[tuple[ControllerName, ...]] = tuple(
    name for name, kind in CONTROLLER_KINDS.items() if kind.uses_predictor
)


@dataclass(frozen=True)
class ControllerSpec:
    """What the user chose on the command line; the controller is built from it once per run."""

    controller: str  # a ControllerName or a registered plugin's name
    predictor: str = "constant_velocity"  # a name accepted by predictors.registry.load_predictor
    flocking: bool = True  # False: omega_floc = 0 (Table III, "NF")
    coupling: Coupling = "ibr"
    record_iterations: bool = False  # keep the humans' prediction of every IBR iteration in ControlOutput
    mpc_overrides: tuple[tuple[str, Any], ...] = ()  # (field, value) pairs applied to mpc.config.MPCConfig
    margins: MarginSpec = MarginSpec()  # allowance for prediction error in Eq. 11 (pipelines/loop/margins.py)

    def __post_init__(self) -> None:
        controller_kind(self.controller)  # UnknownController unless some source registers it
        # Every controller gets a predictor's name (the default, or the user's); predictor_name says
        # whether it plans with it.
        if not (isinstance(self.predictor, str) and self.predictor.strip()):
            raise PipelineError(f"predictor must be a predictor's name (a str), got {self.predictor!r:.60}")
        for name in ("flocking", "record_iterations"):  # a truthy "no" would turn an option on
            if not isinstance(getattr(self, name), bool):
                raise PipelineError(f"{name} must be True or False, got {getattr(self, name)!r:.60}")
        if self.coupling not in COUPLINGS:
            raise PipelineError(f"unknown coupling {self.coupling!r}; choose from {list(COUPLINGS)}")
        if not isinstance(self.margins, MarginSpec):
            raise PipelineError(f"margins must be a MarginSpec, got {self.margins!r}")
        pairs = self.mpc_overrides
        if not (isinstance(pairs, tuple) and all(_is_override(pair) for pair in pairs)):
            raise PipelineError(f"mpc_overrides must be a tuple of (field, value) pairs, got {pairs!r:.60}")
        if any(name == "human_margins" for name, _ in pairs):
            raise PipelineError("set human margins through ControllerSpec.margins, not mpc_overrides")

    @property
    def kind(self) -> ControllerKind:
        return controller_kind(self.controller)

    def behind(self, sensor_range: float | None, sensor_tracks: bool = True) -> ControllerSpec:
        """This spec for robots behind a sensor of ``sensor_range`` m (None: seeing every human), its tracker
        reporting track lengths or not: calibrated margins plan with the block made behind that sensor where
        one is stored (``MarginSpec.behind``)."""
        margins = self.margins.behind(sensor_range, sensor_tracks)
        return self if margins is self.margins else replace(self, margins=margins)

    @property
    def predictor_name(self) -> str | None:
        """The predictor this spec's controller plans with; None for a controller that uses none."""
        return self.predictor if self.kind.uses_predictor else None


def _is_override(pair: object) -> bool:
    """A ``(field, value)`` pair of ``ControllerSpec.mpc_overrides``."""
    return isinstance(pair, tuple) and len(pair) == 2 and isinstance(pair[0], str)


# ---- plugins ---------------------------------------------------------------------------------------------
ENTRY_POINT_GROUP: Final[str] = "crowdmpc.controllers"
PLUGINS_ENV: Final[str] = "CROWDMPC_CONTROLLERS"
# An importable module and a class in it, as for predictor nets (predictors.models.PLUGIN_PATTERN).
PLUGIN_PATTERN: Final[re.Pattern[str]] = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*", re.ASCII)
MAX_PLUGIN_SPEC: Final[int] = 200  # longer is no module path anyone writes; keeps every message one line
CONTROLLER_METHODS: Final[tuple[str, ...]] = ("reset", "act", "describe", "close")


@dataclass(frozen=True)
class ControllerPlugin:
    """A controller class from outside the package, and its facts."""

    name: str  # what --controller and ControllerSpec.controller call it
    cls: type  # built as cls(spec, env_config, jit=jit)
    kind: ControllerKind
    source: str  # "plugin" or "entry point <distribution>"


class UnknownController(PipelineError):
    """A controller name no source registers; for a ``module:Class`` name, the message says how to register
    it (crowdmpc imports a plugin only when the user registers it)."""

    def __init__(self, name: object, choices: list[str]):
        self.name = name
        self.choices = choices
        from predictors.models import registered_plugins

        if is_plugin_spec(name) and name in registered_plugins():  # --plugin took its class for a net
            super().__init__(
                f"controller {name!r} is registered as a predictor net (an nn.Module), not a controller (a "
                "class with reset, act, describe and close, docs/extending.md); a net drives cmpc or dmpc: "
                f"--controller cmpc --predictor NAME, once trained and in the zoo"
            )
            return
        if is_plugin_spec(name):
            super().__init__(
                f"controller {name!r} is a plugin that is not registered; register it with "
                f"`crowdmpc --plugin {name} COMMAND ...` or {PLUGINS_ENV}={name}"
            )
            return
        text = repr(name) if len(repr(name)) <= 60 else f"{repr(name)[:57]}..."
        super().__init__(
            f"unknown controller {text}; choose from {choices}, or register a plugin with --plugin "
            f"module:Class (or ${PLUGINS_ENV}, or an entry point in {ENTRY_POINT_GROUP!r})"
        )

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        # Built from its facts: a process pool sends a job's exception back pickled, and BaseException's
        # pickle calls the class with the message alone (a TypeError, the pool broken).
        return type(self), (self.name, self.choices)


_PLUGINS: dict[str, ControllerPlugin] = {}


def is_shipped(name: object) -> TypeGuard[ControllerName]:
    return isinstance(name, str) and name in CONTROLLER_KINDS


def is_plugin_spec(name: object) -> TypeGuard[str]:
    """Whether ``name`` has the form ``module:Class`` (and a sane length)."""
    return (
        isinstance(name, str) and len(name) <= MAX_PLUGIN_SPEC and PLUGIN_PATTERN.fullmatch(name) is not None
    )


def is_controller_class(obj: object) -> bool:
    """A class with every method of the ``Controller`` protocol: what ``--plugin`` takes for a controller."""
    return inspect.isclass(obj) and all(callable(getattr(obj, m, None)) for m in CONTROLLER_METHODS)


def import_plugin(spec: str) -> object:
    """What ``module:Class`` names, importing the module from the installed packages or, after them, the
    current directory (as ``python -m`` would). PipelineError in one line when it cannot."""
    if not is_plugin_spec(spec):
        text = repr(spec) if len(repr(spec)) <= 60 else f"{repr(spec)[:57]}..."
        raise PipelineError(f"plugin {text} is not of the form module:Class")
    from predictors.errors import PredictorError
    from predictors.plugin_import import import_class

    try:
        return import_class(spec, "plugin")
    except PredictorError as exc:
        raise PipelineError(str(exc)) from None


def plugin_kind(cls: object, name: str) -> ControllerKind:
    """The facts of the controller class ``cls``; PipelineError naming ``name`` unless it is one."""
    if not inspect.isclass(cls):
        raise PipelineError(f"controller {name!r}: {cls!r:.60} is not a class")
    missing = [m for m in CONTROLLER_METHODS if not callable(getattr(cls, m, None))]
    if missing:
        raise PipelineError(
            f"controller {name!r}: {cls.__name__} has no {', '.join(missing)} (the Controller protocol of "
            "pipelines/loop/controllers.py)"
        )
    facts = {fact: getattr(cls, fact, False) for fact in ("uses_predictor", "compiles")}
    for fact, value in facts.items():
        if not isinstance(value, bool):
            raise PipelineError(f"controller {name!r}: {cls.__name__}.{fact} must be a bool, got {value!r}")
    return ControllerKind(**facts)


def load_controller_plugin(spec: str) -> ControllerPlugin:
    """Register the controller class ``module:Class`` (importing its module) under the name ``spec``.

    Registering it again keeps the registration while the module holds the same class, and takes the new
    class once the module was reloaded (``importlib.reload`` after an edit, in a notebook): the first class
    stayed registered, and the edited code never ran."""
    from predictors.plugin_import import reloaded_class

    known = _PLUGINS.get(spec)
    if known is not None and reloaded_class(spec, known.cls) is None:
        return known
    cls = import_plugin(spec)
    plugin = ControllerPlugin(spec, cls, plugin_kind(cls, spec), "plugin")  # type: ignore[arg-type]
    _PLUGINS[spec] = plugin
    return plugin


def register_controller_plugins(specs: Sequence[str]) -> list[ControllerPlugin]:
    """Load each plugin and list it in ``CROWDMPC_CONTROLLERS`` for the processes started after."""
    from predictors.plugin_import import lone_spec

    if (refusal := lone_spec(specs, "module:Class")) is not None:
        raise PipelineError(refusal)
    plugins = [load_controller_plugin(spec) for spec in specs]
    listed = [s for s in os.environ.get(PLUGINS_ENV, "").split(",") if s]
    os.environ[PLUGINS_ENV] = ",".join(dict.fromkeys([*listed, *specs]))
    return plugins


def registered_controller_plugins() -> list[str]:
    """The controller plugins ``module:Class`` registered in this process (``--plugin``, its variable, or
    ``load_controller_plugin`` from Python, which lists none), in their order; entry points are not among
    them."""
    return [name for name, plugin in _PLUGINS.items() if plugin.source == "plugin"]


def _environment_plugins() -> None:
    for spec in os.environ.get(PLUGINS_ENV, "").split(","):
        if spec.strip():
            load_controller_plugin(spec.strip())


def _entry_points() -> dict[str, metadata.EntryPoint]:
    """The installed entry points of ``ENTRY_POINT_GROUP`` by name, not loaded; PipelineError naming the
    distribution when one takes a shipped controller's name (the shipped one ran in its place, without a
    word)."""
    from predictors.plugin_import import shadowing

    points = {}
    for entry in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if is_shipped(entry.name):
            raise PipelineError(shadowing(entry, "controller"))
        points[entry.name] = entry
    return points


def controller_names() -> list[str]:
    """Every name ``ControllerSpec`` accepts: shipped, entry points (named, not loaded) and plugins."""
    _environment_plugins()
    return sorted({*CONTROLLER_KINDS, *_entry_points(), *_PLUGINS})


def controller_plugin(name: str) -> ControllerPlugin:
    """The registered plugin called ``name`` (loading an entry point on first use); UnknownController
    listing the choices when no source registers it. Not for shipped names."""
    if name in _PLUGINS:
        return _PLUGINS[name]
    entry = _entry_points().get(name) if isinstance(name, str) else None
    if entry is not None:
        try:
            cls = entry.load()
        except Exception as exc:
            raise PipelineError(
                f"entry point {name!r} ({entry.value}) does not load: {type(exc).__name__}: {exc}"
            ) from None
        dist = getattr(entry.dist, "name", "?")
        _PLUGINS[name] = ControllerPlugin(name, cls, plugin_kind(cls, name), f"entry point {dist}")
        return _PLUGINS[name]
    _environment_plugins()
    if name in _PLUGINS:
        return _PLUGINS[name]
    raise UnknownController(name, controller_names())


def controller_kind(name: object) -> ControllerKind:
    """The facts of the controller called ``name``, shipped or plugin; UnknownController otherwise."""
    if is_shipped(name):
        return CONTROLLER_KINDS[name]
    if not isinstance(name, str):
        raise UnknownController(name, controller_names())
    return controller_plugin(name).kind
