"""A zoo model trained as a quick check (``train --limit-batches``) is noted once the command takes its
inputs: the note came before refusals it has nothing to do with (its plugin not registered)."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipelines.cli import main
from predictors import models
from predictors.data.prepare import prepare_ewap
from predictors.models import PLUGINS_ENV
from tests.cli_calls import run_cli as run
from tests.pipelines.test_cli_plugins import TOY, _toy_checkpoint
from tests.predictors.samples import write_tiny_ewap

NOTE = (
    "note: 'toy_quick' trained on 1 batch an epoch (train --limit-batches 1): a quick check, not a trained "
    "model (zoo list: *)"
)
COMMANDS = {
    "simulate": ["simulate", "--controller", "cmpc", "--predictor", "toy_quick", "--humans", "2", "--robots",
                 "1", "--episodes", "1", "--no-progress"],
    "sweep": ["sweep", "--experiment", "predictors", "--predictors", "toy_quick", "--humans", "2", "--robots",
              "1", "--backend", "inline", "--dry-run", "--out", "OUT/sweep"],
    "evaluate": ["evaluate", "--predictor", "toy_quick", "--no-progress"],
    "export": ["export", "toy_quick", "--humans", "2", "--robots", "1", "--out", "OUT/x.casadi"],
}  # fmt: skip


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))


def _quick_check_in_the_zoo(tmp_path: Path) -> None:
    """toy_quick in the user zoo: the toy plugin's net, recorded as trained with --limit-batches 1."""
    weights = _toy_checkpoint(tmp_path, "toy_quick", '{"training": {"limit_batches": 1}}')
    assert main(["--plugin", TOY, "zoo", "add", str(weights)]) == 0


def _argv(command: str, tmp_path: Path) -> list[str]:
    return [a.replace("OUT", str(tmp_path)) for a in COMMANDS[command]]


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_no_quick_check_note_before_a_plugin_refusal(command, tmp_path, monkeypatch, capsys):
    """`crowdmpc simulate --predictor toy_quick` without --plugin: the note, then "is a plugin that is not
    registered"; the refusal alone now."""
    _quick_check_in_the_zoo(tmp_path)
    monkeypatch.setattr(models, "_PLUGINS", {})  # a new process, without --plugin
    monkeypatch.delenv(PLUGINS_ENV)
    capsys.readouterr()
    code, _, err = run(capsys, *_argv(command, tmp_path))
    assert code == 2 and "is a plugin that is not registered" in err
    assert err.count("\n") == 1 and "quick check" not in err, err


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_quick_check_is_noted_where_it_runs(command, tmp_path, monkeypatch, capsys):
    _quick_check_in_the_zoo(tmp_path)
    argv = _argv(command, tmp_path)
    if command == "evaluate":
        prepared = tmp_path / "prepared"
        prepare_ewap(
            write_tiny_ewap(tmp_path / "data"), prepared, categorize_scenes=False, log=lambda m: None
        )
        argv += ["--data-dir", str(prepared)]
    capsys.readouterr()
    code, _, err = run(capsys, "--plugin", TOY, *argv)
    named = NOTE.replace("note: ", "note: method 'toy_quick': ") if command == "sweep" else NOTE
    assert code == 0 and err.splitlines().count(named) == 1, err
