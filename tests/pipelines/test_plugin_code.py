"""A plugin's code is recorded beside crowdmpc's: a changed plugin gave the same records as the old one, a
sweep resumed with it said nothing, and review took two runs of one seed by two versions of a plugin for
copies of one episode. ``code_with_plugins()["plugins"]`` names each plugin's file by its sha256."""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import pytest

from pipelines import plugins, version
from pipelines.loop import spec as registry
from predictors import models
from tests.cli_calls import run_cli as run

TOYS = Path(__file__).resolve().parents[1] / "plugins"
TOY = "tests.plugins.toy_controller:StraightLine"
NET = "tests.plugins.toy_predictor:ToyNet"
MINE = "crowdmpc_test_mine:Mine"  # a module of the test's own, written in tmp_path


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(autouse=True)
def _fresh_registries(monkeypatch, tmp_path_factory):
    """No plugin registered before a test, none left after, and the user's module imported afresh."""
    monkeypatch.setattr(registry, "_PLUGINS", {})
    monkeypatch.setattr(models, "_PLUGINS", {})
    monkeypatch.delenv(registry.PLUGINS_ENV, raising=False)
    monkeypatch.delenv(models.PLUGINS_ENV, raising=False)
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))
    yield
    sys.modules.pop(MINE.partition(":")[0], None)
    plugins._module_sha256.cache_clear()


def _mine(folder: Path, speed: float, monkeypatch, edit: str = "") -> Path:
    """The user's plugin: the toy controller at ``speed``, with ``edit`` (a comment); returns its file."""
    path = folder / "crowdmpc_test_mine.py"
    path.write_text(
        f"{edit}from tests.plugins.toy_controller import StraightLine\n\n\n"
        f"class Mine(StraightLine):\n    def __init__(self, *args, **kwargs):\n"
        f"        super().__init__(*args, **kwargs, speed={speed})\n"
    )
    monkeypatch.syspath_prepend(str(folder))
    return path


def test_code_names_each_registered_plugins_file():
    assert "plugins" not in plugins.code_with_plugins()  # none registered: the identity as it always was
    assert plugins.register_plugins([NET, TOY]) == ["model", "controller"]
    assert plugins.code_with_plugins()["plugins"] == {
        NET: _sha256(TOYS / "toy_predictor.py"),
        TOY: _sha256(TOYS / "toy_controller.py"),
    }


def test_a_changed_added_or_dropped_plugin_is_named_among_the_code_changes():
    plugins.register_plugins([TOY])
    now = plugins.code_with_plugins()
    sha = now["plugins"][TOY]
    assert version.code_changes([now], now) == ""
    changed = version.code_changes([{**now, "plugins": {TOY: "a" * 64}}], now)
    assert changed == f"plugin {TOY} {'a' * 12} -> {sha[:12]}"
    without = {k: v for k, v in now.items() if k != "plugins"}
    assert version.code_changes([without], now) == f"plugin {TOY} (none) -> {sha[:12]}"
    dropped = version.code_changes([{**now, "plugins": {TOY: sha, NET: "b" * 64}}], now)
    assert dropped == f"plugin {NET} {'b' * 12} -> (none)"


def test_a_sweep_resumed_with_a_changed_plugin_says_so(tmp_path, capsys, monkeypatch):
    """The sweep records the plugin's file in sweep.json's code; the file changed, its resume notes it, as
    it notes another commit."""
    path = _mine(tmp_path, 0.8, monkeypatch)
    out = tmp_path / "sweep"
    argv = [
        "--plugin", MINE, "sweep", "--experiment", "controllers", "--controllers", MINE, "--humans", "2",
        "--workers", "1", "--jit", "off", "--no-progress", "--out", str(out),
    ]  # fmt: skip
    code, _, err = run(capsys, *argv, "--episodes-per-cell", "1")
    assert code == 0, err
    runs = json.loads((out / "sweep.json").read_text())["runs"]
    assert runs[0]["code"]["plugins"] == {MINE: _sha256(path)}
    first = _sha256(path)
    _mine(tmp_path, 0.7, monkeypatch)  # the user edits the plugin; a new process imports the new file
    sys.modules.pop(MINE.partition(":")[0])
    code, _, err = run(capsys, *argv, "--episodes-per-cell", "2")
    assert code == 0, err
    assert f"holds episodes made by other code (plugin {MINE} {first[:12]} -> {_sha256(path)[:12]})" in err


def test_review_keeps_runs_of_one_seed_by_two_versions_of_a_plugin(tmp_path, capsys, monkeypatch):
    """The same seed by the same commit but another plugin file is another episode, not a copy, and the
    folder's runs are said to come from different code."""
    recorded = tmp_path / "runs"
    shas = []
    for edit in ("", "# the user's edit: the same controller, the same settings\n"):
        path = _mine(tmp_path, 0.8, monkeypatch, edit)
        shas.append(_sha256(path))
        argv = ["--plugin", MINE, "simulate", "--controller", MINE, "--humans", "2", "--episodes", "1"]
        code, _, err = run(capsys, *argv, "--no-progress", "--record", str(recorded / f"v{len(shas)}"))
        assert code == 0, err
        sys.modules.pop(MINE.partition(":")[0])
    code, out, err = run(capsys, "review", str(recorded), "--json", str(tmp_path / "review.json"))
    assert code == 0, err
    review = json.loads((tmp_path / "review.json").read_text())
    assert sorted(r["crowdmpc_plugins"][MINE] for r in review["runs"]) == sorted(shas)
    assert [len(g["files"]) for g in review["groups"]] == [2] and not any(
        g["repeats"] for g in review["groups"]
    )
    assert "recorded by different code" in err and f"with plugins {MINE} {shas[0][:12]}" in err


def test_a_reloaded_plugin_is_named_by_its_new_file(tmp_path, monkeypatch):
    """A notebook edits its plugin and reloads it (importlib.reload keeps the module object): the new class
    runs, and the outputs named the old file's hash, kept once per module."""
    import importlib

    path = _mine(tmp_path, 0.8, monkeypatch)
    plugins.register_plugins([MINE])
    before = plugins.code_with_plugins()["plugins"][MINE]
    assert before == _sha256(path)
    _mine(tmp_path, 0.8, monkeypatch, "# edited\n")
    assert plugins.code_with_plugins()["plugins"][MINE] == before  # the class imported still runs
    importlib.reload(sys.modules[MINE.partition(":")[0]])
    plugins.register_plugins([MINE])
    assert plugins.code_with_plugins()["plugins"][MINE] == _sha256(path) != before


def test_a_pool_worker_loads_the_plugins_its_variables_name(monkeypatch):
    """A net plugin loaded lazily, at a worker's first episode of it, left that worker's earlier recordings
    naming no plugin beside its later ones: the worker loads them as it starts, as the driver does."""
    from pipelines.experiments.process_backend import _load_plugins

    monkeypatch.setenv(models.PLUGINS_ENV, NET)
    assert "plugins" not in plugins.code_with_plugins()
    _load_plugins()
    assert list(plugins.code_with_plugins()["plugins"]) == [NET]
    monkeypatch.setenv(models.PLUGINS_ENV, "tests.plugins.never_imported:Net")
    _load_plugins()  # one that does not load raises in the episodes that use it, not in the pool's start
