"""``crowdmpc --plugin module:Class``: one option for both kinds of plugin, told apart by what the class is.

* a ``torch.nn.Module`` subclass is a predictor net: ``predictors.models.load_plugin`` registers it as the
  model kind ``module:Class`` and lists it in ``CROWDMPC_PLUGINS``;
* a class with the ``Controller`` protocol's methods (``reset``, ``act``, ``describe``, ``close``) is a robot
  controller: ``pipelines.loop.spec`` registers it as the controller ``module:Class`` (``simulate
  --controller module:Class``) and lists it in ``CROWDMPC_CONTROLLERS``.

Either variable is read by the processes a command starts (sweep workers), so they load the same plugins.
Every output records their code beside crowdmpc's: ``code_with_plugins``.
A plugin that does not load is a ``PluginError``: one line, which the command line prints as a parser error;
``load_environment_plugins`` loads those the variables name up front, so that such an error says which
variable named the plugin.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, Final, Literal

from pipelines.errors import PipelineError
from pipelines.loop.spec import PLUGINS_ENV as CONTROLLERS_ENV
from pipelines.loop.spec import (
    import_plugin,
    is_controller_class,
    is_plugin_spec,
    load_controller_plugin,
    register_controller_plugins,
    registered_controller_plugins,
)
from predictors import models
from predictors.errors import PredictorError, short_repr
from predictors.plugin_import import form_hint, lone_spec

PluginKind = Literal["model", "controller"]


class PluginError(PipelineError, PredictorError):
    """A ``--plugin`` that does not load, of either kind (so it is caught as either package's error)."""


def _is_net(obj: object) -> bool:
    torch = sys.modules.get("torch")  # a net's module imported torch; a controller's need not
    return torch is not None and isinstance(obj, type) and issubclass(obj, torch.nn.Module)


def register(spec: str) -> PluginKind:
    """Register the plugin ``module:Class`` (importing its module) as a model kind or a controller, and
    say which."""
    if not is_plugin_spec(spec):
        raise PluginError(
            f"plugin {short_repr(spec)} is not of the form module:NetClass or module:Controller"
            f"{form_hint(spec)}"
        )
    try:
        with _exits_refused(spec):
            obj = import_plugin(spec)
        if is_controller_class(obj) and not _is_net(obj):
            register_controller_plugins([spec])
            return "controller"
        if not _is_net(obj):
            raise PluginError(
                f"model {spec!r}: {short_repr(obj)} is not a torch.nn.Module subclass (a predictor net), nor "
                "a controller class with reset, act, describe and close (pipelines/loop/controllers.py)"
            )
        models.register_plugins([spec])
    except PluginError:
        raise
    except (PipelineError, PredictorError) as exc:
        raise PluginError(str(exc)) from None
    return "model"


def register_plugins(specs: Sequence[str]) -> list[PluginKind]:
    """``register`` each of ``specs``, in order (what ``crowdmpc --plugin`` calls)."""
    if (refusal := lone_spec(specs, "module:Class")) is not None:
        raise PluginError(refusal)
    return [register(spec) for spec in specs]


@contextlib.contextmanager
def _exits_refused(spec: str) -> Iterator[None]:
    """A plugin module that calls ``sys.exit`` while it is imported is a ``PluginError``, not the end of
    crowdmpc with the plugin's exit status and no word. Ctrl-C (KeyboardInterrupt) still goes through."""
    try:
        yield
    except SystemExit as exc:
        module = spec.partition(":")[0]
        raise PluginError(
            f"plugin {spec!r}: importing {module!r} failed: it called sys.exit({short_repr(exc.code)}); "
            "a plugin module defines classes and must not exit"
        ) from None


# The variables that name plugins (what --plugin sets for the processes it starts), and how each is loaded.
ENVIRONMENT: Final[dict[str, Callable[[str], object]]] = {
    models.PLUGINS_ENV: models.load_plugin,
    CONTROLLERS_ENV: load_controller_plugin,
}


def load_environment_plugins() -> None:
    """Load the plugins ``$CROWDMPC_PLUGINS`` and ``$CROWDMPC_CONTROLLERS`` name (each once; later lookups
    find them registered). A plugin that does not load is a ``PluginError`` naming the variable: loaded
    lazily, its error surfaced inside whichever option first looked a name up ("argument --model: ...")."""
    for variable, load in ENVIRONMENT.items():
        for spec in (s.strip() for s in os.environ.get(variable, "").split(",")):
            if not spec:
                continue
            try:
                with _exits_refused(spec):
                    load(spec)
            except (PipelineError, PredictorError) as exc:
                raise PluginError(f"${variable}: {exc}") from None


def plugin_environment() -> dict[str, str]:
    """The plugin variables a process this one starts needs: each lists what it lists now and every plugin
    registered here. A sweep's pool workers are spawned (on every OS), so they hold nothing this process
    imported: a script that registered with ``load_controller_plugin`` or ``load_plugin`` (which list
    nothing) had every episode refused in the workers ("... is a plugin that is not registered"), where
    the same sweep inline ran."""
    registered = {
        models.PLUGINS_ENV: models.registered_plugins(),
        CONTROLLERS_ENV: registered_controller_plugins(),
    }
    from predictors.plugin_import import FOLDERS_ENV, plugin_folders

    environment = {}
    listed_folders = [f for f in os.environ.get(FOLDERS_ENV, "").split(os.pathsep) if f]
    if folders := list(dict.fromkeys([*listed_folders, *plugin_folders()])):
        environment[FOLDERS_ENV] = os.pathsep.join(folders)
    for variable, specs in registered.items():
        for spec in specs:
            _check_importable_elsewhere(spec)
        listed = [s.strip() for s in os.environ.get(variable, "").split(",") if s.strip()]
        if listed or specs:
            environment[variable] = ",".join(dict.fromkeys([*listed, *specs]))
    return environment


def _check_importable_elsewhere(spec: str) -> None:
    """PipelineError unless a new interpreter can import ``spec``'s class. One of an interactive session's
    ``__main__`` (a notebook, ``python -c``: no file, no module name) it cannot: a spawned worker's
    ``__main__`` is its own, so every episode failed there, those of the shipped controllers too (their
    build lists the plugins), with "module '__main__' has no ...". A script's ``__main__`` (or that of
    ``python -m``) each worker imports again, and finds the class."""
    module, _, name = spec.partition(":")
    main = sys.modules.get("__main__")
    if module != "__main__" or getattr(main, "__spec__", None) is not None:
        return
    path = getattr(main, "__file__", None)
    if isinstance(path, str) and os.path.isfile(path):
        return
    raise PipelineError(
        f"plugin {spec!r} is a class of this interactive session (a notebook, python -c), which the sweep's "
        f"worker processes cannot import (each is a new interpreter); put it in a module file and register "
        f"'module:{name}', or run the sweep with backend 'inline'"
    )


def code_with_plugins() -> dict[str, Any]:
    """The code a run ran: ``pipelines.version.code_identity()`` and, with plugins registered, ``"plugins"``
    (``plugin_code()``): a changed plugin gave the same records as the old one, and a sweep resumed with it
    said nothing."""
    from pipelines.version import code_identity

    identity: dict[str, Any] = dict(code_identity())
    files = plugin_code()
    if files:
        identity["plugins"] = files
    return identity


def plugin_code() -> dict[str, str | None]:
    """``module:Class`` -> the sha256 of the file its module was imported from, for each plugin registered
    in this process (predictor nets, then controllers; entry points, installed packages with a version of
    their own, are not among them). The module's own file only: code it imports from other files is not
    covered. None for a module with no file (a notebook's ``__main__``)."""
    specs = [*models.registered_plugins(), *registered_controller_plugins()]
    out = {}
    for spec in specs:
        module, _, name = spec.partition(":")
        out[spec] = _module_sha256(module, getattr(sys.modules.get(module), name, None))
    return out


@functools.cache
def _module_sha256(module: str, plugin_class: object) -> str | None:
    """Once per class object (held by the cache, so that its id is never another's): the code that runs is
    the code imported, however its file changes afterwards; a module reloaded (``importlib.reload``, a
    notebook) makes a new class, whose file is read again."""
    path = getattr(sys.modules.get(module), "__file__", None)
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest() if path else None
    except OSError:
        return None
