"""Importing user code named ``module:Class``: the step shared by net plugins (``predictors.models``) and
controller plugins (``pipelines.loop.spec``), whose registries keep what it imports.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import os
import sys
from pathlib import Path, PurePath
from typing import Any, Final

from predictors.errors import PredictorError

# The folders the plugins were imported from, for the processes this one starts (pipelines.plugins)
FOLDERS_ENV: Final[str] = "CROWDMPC_PLUGIN_FOLDERS"


def lone_spec(specs: object, form: str) -> str | None:
    """The one-line refusal of one ``module:Class`` given where a list of them is due, else None: a str is
    iterable, and its letters were taken for plugins ("plugin 'w' is not of the form module:NetClass")."""
    if isinstance(specs, str):
        return f"plugins are a list of {form!r} strings, got the str {specs!r}: write [{specs!r}]"
    return None


def import_class(spec: str, what: str = "plugin") -> object:
    """What ``module:Class`` names (the form is the caller's to check), importing the module from the
    installed packages or, after them, the current directory, as ``python -m`` would: a user's one-file
    plugin next to where they work needs no install, and never shadows an installed module. PredictorError
    in one line, naming ``what`` and ``spec``, when it cannot. Shared by net and controller plugins."""
    cwd = str(Path.cwd())
    _search_after_installed(cwd)
    module_name, _, class_name = spec.partition(":")
    imported_before = module_name in sys.modules
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # a plugin module that does not import: say which and why, in one line
        raise PredictorError(
            f"{what} {spec!r}: importing {module_name!r} failed: {type(exc).__name__}: {exc}"
            f"{_not_found_hint(exc, module_name, class_name, cwd)}"
        ) from None
    if not hasattr(module, class_name):
        if (yours := _shadowed_file(module_name, module, Path(cwd))) is not None:
            where = getattr(module, "__file__", None) or "built in"
            raise PredictorError(
                f"{what} {spec!r}: module {module_name!r} is {where}, not your {yours}: an installed module "
                "(or crowdmpc's own) of that name comes first; rename your file"
            )
        # A notebook that wrote the class after a first try: import_module hands back the module as it
        # was first imported, and the refusal repeated itself with nothing saying why.
        reload = (
            f"; if you added it since the module was imported, importlib.reload({module_name}) first (Python "
            "keeps a module as it was first imported)"
            if imported_before
            else ""
        )
        raise PredictorError(f"{what} {spec!r}: module {module_name!r} has no {class_name!r}{reload}")
    return getattr(module, class_name)


def form_hint(spec: object) -> str:
    """For a spec that is not ``module:Class`` because it names a file (``./window_mlp.py:WindowMLP``,
    ``window_mlp.py``), the spec to write instead, in brackets; else "" (a spec longer than
    ``models.MAX_PLUGIN_SPEC``, 200, is no path anyone typed, and its hint would flood the line)."""
    if not isinstance(spec, str) or len(spec) > 200:
        return ""
    path, colon, class_name = spec.partition(":")
    if not ("/" in path or path.endswith(".py")):
        return ""
    stem = PurePath(path).stem
    return (
        f" (a module's name as Python imports it, not a file: run crowdmpc from the folder that holds "
        f"{stem}.py and write {stem}:{class_name if colon and class_name else 'ClassName'})"
    )


def _not_found_hint(exc: Exception, module_name: str, class_name: str, cwd: str) -> str:
    """What to do when the plugin's own module was not found (not a module it imports): "No module named
    'window_mlp'" said nothing of where crowdmpc looked, when the user ran it from another folder than the
    file's, or named the file (window_mlp.py:WindowMLP) for the module."""
    if not isinstance(exc, ModuleNotFoundError) or exc.name is None:
        return ""
    if not (module_name == exc.name or module_name.startswith(exc.name + ".")):
        return ""  # a module the plugin imports is missing: the message names it
    if module_name.endswith(".py"):
        return f" (name the module, not its file: {module_name[:-3]}:{class_name})"
    top = module_name.partition(".")[0]
    return (
        f" (not installed, and no {top}.py nor {top}/ in the folder crowdmpc runs in, {cwd}: run it from "
        f"the folder that holds {top}.py, or put that folder on PYTHONPATH)"
    )


class _AfterInstalled(importlib.abc.MetaPathFinder):
    """Finds top-level modules in ``folder`` once every other finder has had its turn. Appending the folder
    to ``sys.path`` was not enough: an editable install (the README's ``pip install -e``) is found by a
    finder that Python asks after every ``sys.path`` entry, so a stray ``mpc.py`` beside the plugin became
    crowdmpc's ``mpc`` in a sweep's fresh workers ("No module named 'mpc.cmpc'; 'mpc' is not a package")."""

    def __init__(self, folder: str):
        self.folder = folder

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> Any:
        if path is not None:  # a submodule: its package's own __path__ finds it
            return None
        return importlib.machinery.PathFinder.find_spec(fullname, [self.folder])


def _search_after_installed(folder: str) -> None:
    """Put an ``_AfterInstalled`` finder for ``folder`` last on ``sys.meta_path`` (once)."""
    if folder not in plugin_folders():
        sys.meta_path.append(_AfterInstalled(folder))


def plugin_folders() -> list[str]:
    """The folders this process imports plugins from (``import_class``'s working folders), in order."""
    return [f.folder for f in sys.meta_path if isinstance(f, _AfterInstalled)]


def search_listed_folders() -> None:
    """Search the folders ``FOLDERS_ENV`` lists as ``import_class`` searches its own: a sweep's worker,
    before it moves to its scratch folder (jit), where its plugins are not (every episode raised "No module
    named ..." once the folder was no longer on sys.path, the cmpc column's too)."""
    for folder in os.environ.get(FOLDERS_ENV, "").split(os.pathsep):
        if folder:
            _search_after_installed(folder)


def _shadowed_file(module_name: str, module: object, cwd: Path) -> Path | None:
    """The user's file or folder in ``cwd`` that ``module_name`` was meant to import, when the module
    imported is another one (an installed package's, or crowdmpc's own ``mpc``): None otherwise."""
    top = module_name.partition(".")[0]
    candidates = [cwd / f"{top}.py", cwd / top]
    yours = next((p for p in candidates if p.is_file() or (p / "__init__.py").is_file()), None)
    if yours is None:
        return None
    where = getattr(module, "__file__", None)
    mine = yours if yours.is_file() else yours / "__init__.py"
    try:  # the same file, not one under cwd: a link in cwd to a file elsewhere is the user's all the same
        same = where is not None and os.path.samefile(where, mine)
    except OSError:
        same = False
    return None if same else yours


def reloaded_class(spec: str, registered: object) -> object | None:
    """The class ``module:Class`` names now, when its module, imported, holds another one than
    ``registered``: the user reloaded it after an edit (``importlib.reload``, in a notebook), and registering
    it again must take the edited class, where the first one stayed registered and the edit never ran.
    None when it holds ``registered``, or is not imported (nothing is imported here)."""
    module_name, _, class_name = spec.partition(":")
    module = sys.modules.get(module_name)
    current = getattr(module, class_name, None) if module is not None else None
    return None if current is None or current is registered else current


def shadowing(entry: Any, what: str) -> str:
    """The one-line refusal of an installed entry point that takes the name of a shipped ``what`` (a model
    kind, or a controller: ``pipelines.loop.spec``)."""
    dist = getattr(getattr(entry, "dist", None), "name", None) or "?"
    return (
        f"entry point {entry.name!r} ({entry.value}) of distribution {dist!r} would shadow a shipped {what}; "
        f"rename it in {dist}'s {entry.group!r} entry points or uninstall {dist}"
    )
