"""The explicit registry of trainable predictor networks ("model kinds"), shipped ones and plugins.

A model kind (``predictors.kinds.ModelKind``, which this module still exports) is a net class that keeps
the step contract (``predictors.nets.contract``) plus the config values that make it this kind
(``vanilla_lstm`` is ``SocialLSTM`` without pooling). ``train --model``, the zoo's ``"model"`` field and
``export`` name kinds. Three sources, in this order:

* the shipped kinds (``SHIPPED``);
* installed packages' entry points in the group ``crowdmpc.predictors`` (``name = "module:NetClass"``);
* ``module:NetClass`` given by the user: ``--plugin module:NetClass`` on the command line, or the
  ``CROWDMPC_PLUGINS`` environment variable (comma-separated), which the command line sets so that sweep
  workers see the same plugins. The kind's name is ``module:NetClass``.

A zoo config that names a kind no source registers is refused with a message that says how to register it:
a file in a zoo never makes crowdmpc import code by itself.
"""

from __future__ import annotations

import os
import re
from importlib import metadata
from typing import Any, Final

from predictors.errors import PredictorError, short_repr
from predictors.kinds import ModelKind
from predictors.plugin_import import form_hint, import_class, lone_spec, reloaded_class, shadowing

ENTRY_POINT_GROUP: Final[str] = "crowdmpc.predictors"
PLUGINS_ENV: Final[str] = "CROWDMPC_PLUGINS"
# A plugin is named as an importable module and a class in it: dotted identifiers, nothing else.
PLUGIN_PATTERN: Final[re.Pattern[str]] = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*", re.ASCII)
# A longer spec is no module path anyone writes; refusing it keeps every message about it one short line.
MAX_PLUGIN_SPEC: Final[int] = 200


class UnknownModel(PredictorError):
    """A model kind that no source registers. A name of the form ``module:NetClass`` is a plugin that was not
    loaded: the message says how to load it (crowdmpc never imports a module because a file names it)."""

    def __init__(self, name: object, choices: list[str]):
        self.name = name
        self.choices = choices
        if isinstance(name, str) and len(name) <= MAX_PLUGIN_SPEC and PLUGIN_PATTERN.fullmatch(name):
            super().__init__(
                f"model {name!r} is a plugin that is not registered; register it with "
                f"`crowdmpc --plugin {name} COMMAND ...` or {PLUGINS_ENV}={name}"
            )
            return
        super().__init__(
            f"unknown model {short_repr(name)}; choose from {choices}, or register a plugin with "
            f"--plugin module:NetClass (or ${PLUGINS_ENV}, or an entry point in {ENTRY_POINT_GROUP!r})"
        )

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        return type(self), (self.name, self.choices)  # see predictors.errors.DatasetFormatError.__reduce__


def _shipped() -> dict[str, ModelKind]:
    from predictors.nets.social_attention import SocialAttention
    from predictors.nets.social_gan import GENERATOR_DEFAULTS
    from predictors.nets.social_gru import SocialGRU
    from predictors.nets.social_lstm import SocialLSTM

    kinds = [
        ModelKind(
            "social_lstm",
            SocialLSTM,
            {"pooling": "grid"},
            refused={
                "pooling": (
                    lambda v: v == "none",
                    "without social pooling it is a vanilla_lstm; choose that kind",
                ),
                "noise_dim": (lambda v: v != 0, "noise makes it the social_gan generator; choose that kind"),
            },
        ),
        ModelKind(
            "vanilla_lstm",
            SocialLSTM,
            {"pooling": "none"},
            defining={"pooling": "it has no social pooling"},
            refused={"noise_dim": (lambda v: v != 0, "noise makes it a GAN generator")},
        ),
        ModelKind(
            "social_gan",
            SocialLSTM,
            dict(GENERATOR_DEFAULTS),
            adversarial=True,
            refused={
                "noise_dim": (
                    lambda v: v == 0,
                    "the generator draws its variety from noise; give noise_dim >= 1",
                ),
                "head": (lambda v: v != "point", "its discriminator judges points; give head 'point'"),
            },
        ),
        ModelKind("social_gru", SocialGRU),
        ModelKind("social_attention", SocialAttention),
    ]
    return {kind.name: kind for kind in kinds}


_SHIPPED: dict[str, ModelKind] = {}
_PLUGINS: dict[str, ModelKind] = {}


def shipped() -> dict[str, ModelKind]:
    if not _SHIPPED:
        _SHIPPED.update(_shipped())
    return dict(_SHIPPED)


def load_plugin(spec: str) -> ModelKind:
    """Register ``module:NetClass`` (importing the module) and return its kind, named ``spec``.

    The module is looked up among the installed ones, then in the current directory: a user's
    one-file plugin next to where they work needs no install."""
    if not isinstance(spec, str) or len(spec) > MAX_PLUGIN_SPEC or PLUGIN_PATTERN.fullmatch(spec) is None:
        raise PredictorError(f"plugin {short_repr(spec)} is not of the form module:NetClass{form_hint(spec)}")
    known = _PLUGINS.get(spec)
    if known is not None and reloaded_class(spec, known.net_class) is None:
        return known
    if spec in shipped():
        raise PredictorError(f"plugin {spec!r} would shadow a shipped model")
    cls = import_class(spec, "plugin")
    kind = ModelKind(spec, cls, defaults=dict(getattr(cls, "kind_defaults", {})), source="plugin")  # type: ignore[arg-type]
    _PLUGINS[spec] = kind
    return kind


def register_plugins(specs: list[str] | tuple[str, ...]) -> list[ModelKind]:
    """Load each plugin and record it in ``CROWDMPC_PLUGINS`` so that child processes (sweep workers) load it
    as well."""
    if (refusal := lone_spec(specs, "module:NetClass")) is not None:
        raise PredictorError(refusal)
    kinds = [load_plugin(spec) for spec in specs]
    listed = [s for s in os.environ.get(PLUGINS_ENV, "").split(",") if s]
    os.environ[PLUGINS_ENV] = ",".join(dict.fromkeys([*listed, *specs]))
    return kinds


def registered_plugins() -> list[str]:
    """The plugins ``module:NetClass`` registered in this process (``--plugin``, its variable, or
    ``load_plugin`` from Python, which lists none), in their order; entry points are not among them."""
    return [name for name, kind in _PLUGINS.items() if kind.source == "plugin"]


def _environment_plugins() -> None:
    for spec in os.environ.get(PLUGINS_ENV, "").split(","):
        if spec.strip():
            load_plugin(spec.strip())


def _entry_points() -> dict[str, Any]:
    """The installed entry points of ``ENTRY_POINT_GROUP`` by name, not loaded; PredictorError naming the
    distribution when one takes a shipped kind's name (the shipped kind ran in its place, without a word,
    where ``--plugin`` refuses the like)."""
    points = {}
    for entry in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if entry.name in shipped():
            raise PredictorError(shadowing(entry, "model"))
        points[entry.name] = entry
    return points


def model_kinds() -> dict[str, ModelKind]:
    """Every registered kind by name: shipped, then entry points (loaded), then plugins."""
    kinds = shipped()
    for name in _entry_points():  # none takes a shipped name: _entry_points refuses that
        kinds[name] = model_kind(name)
    _environment_plugins()
    kinds.update(_PLUGINS)
    return kinds


def model_names() -> list[str]:
    """The names ``model_kind`` accepts, importing nothing new (entry points are named, not loaded)."""
    _environment_plugins()
    return sorted({*shipped(), *_entry_points(), *_PLUGINS})


def model_kind(name: object) -> ModelKind:
    """The kind called ``name``; ``UnknownModel`` (listing the choices) when no source registers it."""
    if not isinstance(name, str):
        raise UnknownModel(name, model_names())
    kinds = shipped()
    if name in kinds:
        _entry_points()  # refused when one shadows a shipped kind
        return kinds[name]
    if name in _PLUGINS:
        return _PLUGINS[name]
    entry = _entry_points().get(name)
    if entry is not None:
        if name not in _PLUGINS:
            try:
                cls = entry.load()
            except Exception as exc:
                raise PredictorError(
                    f"entry point {name!r} ({entry.value}) does not load: {type(exc).__name__}: {exc}"
                ) from None
            dist = getattr(entry.dist, "name", "?")
            _PLUGINS[name] = ModelKind(
                name, cls, defaults=dict(getattr(cls, "kind_defaults", {})), source=f"entry point {dist}"
            )
        return _PLUGINS[name]
    _environment_plugins()
    if name in _PLUGINS:
        return _PLUGINS[name]
    raise UnknownModel(name, model_names())
