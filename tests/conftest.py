import os

import pytest

from pipelines.loop.spec import PLUGINS_ENV as CONTROLLER_PLUGINS_ENV
from predictors.models import PLUGINS_ENV
from predictors.zoo import ZOO_ENV


@pytest.fixture(scope="session")
def _session_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("crowdmpc_cache")


@pytest.fixture(autouse=True)
def _private_cache_root(_session_cache, monkeypatch):
    """Compiled solvers and prepared data go to one cache of this test session, never ~/.cache/crowdmpc
    (tests/predictors gives each of its tests a fresh one)."""
    monkeypatch.setenv("CROWDMPC_CACHE", str(_session_cache))


@pytest.fixture(autouse=True)
def _no_ray_cluster_from_the_environment(monkeypatch):
    """A sweep joins the cluster $RAY_ADDRESS names, as ray.init does (pipelines.experiments.ray_join):
    under a developer's exported RAY_ADDRESS, the Ray tests' local sweeps ran on that cluster. A test that
    means one sets it."""
    monkeypatch.delenv("RAY_ADDRESS", raising=False)


@pytest.fixture(autouse=True)
def _private_user_zoo(tmp_path_factory, monkeypatch):
    """Every test gets an empty user zoo of its own (never the real ~/.local/share/crowdmpc/zoo), and no
    plugins from the environment; what a test sets (``--plugin`` sets CROWDMPC_PLUGINS or
    CROWDMPC_CONTROLLERS) is undone after."""
    monkeypatch.setenv(ZOO_ENV, str(tmp_path_factory.mktemp("user_zoo")))
    monkeypatch.delenv(PLUGINS_ENV, raising=False)
    monkeypatch.delenv(CONTROLLER_PLUGINS_ENV, raising=False)
    yield
    # monkeypatch restores only what it changed: a variable absent before the test, and set by its --plugin,
    # stayed, and a later test's monkeypatch.undo() put it back mid-test (a plugin of a gone tmp_path). Its
    # undo first: a test that deleted the variable its --plugin set (monkeypatch.delenv, as a new process) had
    # it set again by the undo that came after this clean-up, for the rest of the session
    # (tests/test_plugin_env_isolation.py).
    monkeypatch.undo()
    for variable in (PLUGINS_ENV, CONTROLLER_PLUGINS_ENV):
        os.environ.pop(variable, None)


@pytest.fixture(autouse=True, scope="session")
def _no_plugins_from_collection():
    """No plugin registered while the test modules were imported (tests/predictors/test_contract.py's
    parametrisation lists the kinds with its toy plugin among them): it was in the registry for every test of
    the session, and every recording named its code. A test that needs one registers it."""
    from pipelines.loop import spec
    from predictors import models

    for registry in (spec._PLUGINS, models._PLUGINS):
        for name in [name for name, entry in registry.items() if entry.source == "plugin"]:
            del registry[name]


@pytest.fixture(autouse=True)
def _plugins_of_this_test_only(monkeypatch):
    """The plugin registries as they were before the test, after it: a plugin one test registered stayed
    registered for every later test, whose outputs then named its code (``code_with_plugins``)."""
    from pipelines.loop import spec
    from predictors import models

    monkeypatch.setattr(spec, "_PLUGINS", dict(spec._PLUGINS))
    monkeypatch.setattr(models, "_PLUGINS", dict(models._PLUGINS))


@pytest.fixture
def sigint_as_at_a_terminal():
    """SIGINT delivered to this process, and to the programs it starts, as a terminal's Ctrl-C is: a test
    run started in the background (``make test &``) inherits SIGINT ignored, and so would every child."""
    import signal

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.fixture(autouse=True)
def _lightning_logs_to_this_tests_stderr():
    """Lightning's loggers print through a StreamHandler made as lightning is imported, on the sys.stderr of
    that moment: a test under capsys that imported it first left them writing to a closed capture, so that a
    later test's Lightning message came out as "--- Logging error --- Traceback ..." (test_train_storage's
    check of no traceback failed after test_train_output, run alone as a pair). Each test's handlers write
    to its own sys.stderr."""
    import logging
    import sys

    for name in ("lightning", "lightning.pytorch", "lightning.fabric"):
        if name in logging.Logger.manager.loggerDict:  # not imported: nothing to repoint (and no import)
            for handler in logging.getLogger(name).handlers:
                if type(handler) is logging.StreamHandler:
                    handler.stream = sys.stderr  # not setStream, which flushes the closed one first
