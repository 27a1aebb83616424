"""How many epochs a run trains in all (pipelines.commands.train_epochs): a resume without --epochs trained
to the default 25, not to the count the run was started with (a killed 3-epoch run ended as another run)."""

import json

import pytest
import torch

from pipelines.cli import main
from pipelines.commands.train_resume import SETTINGS_FILE
from tests.predictors.samples import write_walk_file


def _train(tmp_path, *extra: str) -> int:
    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    args = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--no-progress"]
    return main([*args, "--out", str(tmp_path / "run"), *extra])


def _settings(tmp_path) -> dict:
    return json.loads((tmp_path / "run" / SETTINGS_FILE).read_text())


def _rewrite_settings(tmp_path, **changes) -> None:
    settings = {k: v for k, v in {**_settings(tmp_path), **changes}.items() if v is not None}
    (tmp_path / "run" / SETTINGS_FILE).write_text(json.dumps(settings))


def _epochs_done(tmp_path) -> int:
    last = torch.load(tmp_path / "run" / "checkpoints" / "last.ckpt", weights_only=True)
    return int(last["epoch"]) + 1


def test_a_new_run_records_its_count(tmp_path):
    assert _train(tmp_path, "--epochs", "1") == 0
    assert _settings(tmp_path)["epochs"] == 1


def test_the_help_says_a_resume_takes_the_runs_count(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "training epochs in all (default 25; with --resume, the run's last --epochs)" in help_text


def test_a_resume_without_epochs_trains_to_the_runs_count(tmp_path, capsys):
    """As a run started with --epochs 3 and killed after its first epoch: the resume ends at 3, not 25."""
    assert _train(tmp_path, "--epochs", "1") == 0
    _rewrite_settings(tmp_path, epochs=3)
    (tmp_path / "run" / "vanilla_lstm_custom.metrics.json").unlink()  # killed before its metrics
    capsys.readouterr()
    assert _train(tmp_path, "--resume") == 0
    assert "goes on with the run's epochs 3" in capsys.readouterr().err
    assert _epochs_done(tmp_path) == 3
    record = json.loads((tmp_path / "run" / "vanilla_lstm_custom.json").read_text())
    assert record["training"]["epochs"] == 3


def test_a_resume_with_more_epochs_is_the_count_the_next_resume_takes(tmp_path, capsys):
    assert _train(tmp_path, "--epochs", "1") == 0
    assert _train(tmp_path, "--resume", "--epochs", "2") == 0
    assert _settings(tmp_path)["epochs"] == 2 and _epochs_done(tmp_path) == 2
    capsys.readouterr()
    assert _train(tmp_path, "--resume") == 2  # finished at its 2: nothing left, as --epochs 2 says
    assert "has trained 2 epochs already; --epochs 2 would train none" in capsys.readouterr().err


def test_a_run_that_recorded_no_count_needs_epochs_typed(tmp_path, capsys):
    """Runs from before the count was kept: 25 would be a guess, so the resume asks."""
    assert _train(tmp_path, "--epochs", "1") == 0
    _rewrite_settings(tmp_path, epochs=None)
    capsys.readouterr()
    assert _train(tmp_path, "--resume") == 2
    err = capsys.readouterr().err
    assert "does not record how many epochs it trains in all" in err and "give --epochs N" in err
    assert err.count("\n") == 1
    assert _train(tmp_path, "--resume", "--epochs", "2") == 0
    assert _epochs_done(tmp_path) == 2 and _settings(tmp_path)["epochs"] == 2


def test_a_finished_runs_metrics_nested_past_the_stack_is_no_traceback(tmp_path, capsys):
    """`train --resume --epochs 2` of a run whose NAME.metrics.json was nested 100,000 deep ended in
    "RecursionError: maximum recursion depth exceeded while decoding a JSON array": the check of a stop by
    --patience caught the ValueError of other damage only. It now reads such a file as it reads those."""
    assert _train(tmp_path, "--epochs", "1") == 0
    (tmp_path / "run" / "vanilla_lstm_custom.metrics.json").write_text("[" * 100_000)
    capsys.readouterr()
    assert _train(tmp_path, "--resume", "--epochs", "2") == 0
    assert _epochs_done(tmp_path) == 2
