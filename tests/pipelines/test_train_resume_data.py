"""`crowdmpc train --resume` goes on with the run's data: its --train/--val/--test files, or its protocol,
dataset and data directory, wherever the command line types no data option (it had to name them again, and
a resume whose $CROWDMPC_DATA was unset could not find the run's prepared files)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from pipelines.cli import main
from predictors.data.prepare import prepare_ewap
from tests.predictors.samples import write_tiny_ewap, write_walk_file


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))


def _train(*args: str) -> int:
    return main(["train", "--model", "vanilla_lstm", "--no-progress", *args])


def test_a_run_of_explicit_files_resumes_without_naming_them(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("CROWDMPC_DATA", raising=False)  # the default protocol's files cannot stand in
    walk = write_walk_file(tmp_path / "walk.ndjson")
    other = write_walk_file(tmp_path / "other.ndjson")
    out = tmp_path / "run"
    files = ["--train", str(walk), "--val", str(walk), "--test", str(other)]
    assert _train(*files, "--batch-size", "2", "--epochs", "1", "--out", str(out)) == 0
    settings = json.loads((out / "train_settings.json").read_text())
    assert settings["data"] == {"explicit": True} and "data_dir" not in settings
    first = json.loads((out / "vanilla_lstm_custom.metrics.json").read_text())["training_data"]
    capsys.readouterr()

    assert _train("--epochs", "2", "--out", str(out), "--resume") == 0
    err = capsys.readouterr().err
    assert f"--resume: {out} goes on with the run's batch_size 2, its data files\n" in err
    resumed = json.loads((out / "vanilla_lstm_custom.metrics.json").read_text())
    assert resumed["training_data"] == first and resumed["protocol"] == "custom"
    assert json.loads((out / "vanilla_lstm_custom.json").read_text())["training"]["epochs"] == 2

    # typed, the files are the command's: other ones than the run's are refused, naming the files
    assert (
        _train("--train", str(other), "--val", str(walk), "--epochs", "3", "--out", str(out), "--resume") == 2
    )
    err = capsys.readouterr().err
    assert "was started with other settings (files: run" in err and "other.ndjson" in err
    assert err.count("\n") == 1


def test_a_protocol_run_resumes_with_its_dataset_and_data_directory(tmp_path, capsys, monkeypatch):
    prepared = tmp_path / "prepared"
    prepare_ewap(write_tiny_ewap(tmp_path / "data"), prepared, categorize_scenes=False, log=lambda msg: None)
    out = tmp_path / "run"
    monkeypatch.delenv("CROWDMPC_DATA", raising=False)
    common = ["--batch-size", "4", "--limit-batches", "1", "--out", str(out)]
    assert _train("--data-dir", str(prepared), "--dataset", "biwi_hotel", "--epochs", "1", *common) == 0
    settings = json.loads((out / "train_settings.json").read_text())
    assert settings["data"] == {"protocol": "paper", "dataset": "biwi_hotel"}
    assert settings["data_dir"] == str(prepared.resolve())
    capsys.readouterr()

    assert _train("--epochs", "2", "--out", str(out), "--resume") == 0
    err = capsys.readouterr().err
    shown = f"batch_size 4, limit_batches 1, dataset biwi_hotel, data directory {prepared.resolve()}\n"
    assert f"--resume: {out} goes on with the run's {shown}" in err
    record = json.loads((out / "vanilla_lstm_hotel.metrics.json").read_text())
    assert record["protocol"] == "paper" and record["training"]["epochs"] == 2
    assert sorted(record["training_data"]["files"]["test"]) == ["test/biwi_hotel.ndjson"]

    # $CROWDMPC_DATA names the data directory then, and is not overridden by the run's
    monkeypatch.setenv("CROWDMPC_DATA", str(tmp_path / "nowhere"))
    assert _train("--epochs", "3", "--out", str(out), "--resume") == 2
    assert "nowhere does not exist" in capsys.readouterr().err
    # a data option typed: the others are the defaults again, and the run's test file is not the default's
    monkeypatch.delenv("CROWDMPC_DATA")
    assert _train("--data-dir", str(prepared), "--epochs", "3", "--out", str(out), "--resume") == 2
    err = capsys.readouterr().err
    assert "was started with other settings (files: run" in err and "biwi_eth.ndjson" in err
    assert (
        _train(
            "--data-dir", str(prepared), "--dataset", "biwi_hotel", "--epochs", "3", *common[4:], "--resume"
        )
        == 0
    )
    assert json.loads((out / "vanilla_lstm_hotel.json").read_text())["training"]["epochs"] == 3


def test_a_run_from_before_its_data_was_recorded_resumes_as_before(tmp_path, capsys, monkeypatch):
    """No "data" in its settings: nothing is taken, and the default protocol wants a data directory."""
    walk = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    files = ["--train", str(walk), "--val", str(walk)]
    assert _train(*files, "--epochs", "1", "--out", str(out)) == 0
    path = out / "train_settings.json"
    settings = json.loads(path.read_text())
    del settings["data"]
    path.write_text(json.dumps(settings))
    capsys.readouterr()
    monkeypatch.delenv("CROWDMPC_DATA", raising=False)
    assert _train("--epochs", "2", "--out", str(out), "--resume") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no data directory: pass --data-dir" in err
    assert _train(*files, "--epochs", "2", "--out", str(out), "--resume") == 0


def test_a_resume_whose_data_directory_gives_other_files_is_refused_before_preparing(
    tmp_path, capsys, monkeypatch
):
    """A run trained with --data-dir on prepared data, resumed in a shell whose $CROWDMPC_DATA names the raw
    data (as the README has it set): the resume prepared that raw data (minutes) and then refused the run's
    files in a line cut short ("files: run {...}, now {...}") that named no data directory."""
    prepared = tmp_path / "prepared"
    prepare_ewap(write_tiny_ewap(tmp_path / "data"), prepared, categorize_scenes=False, log=lambda msg: None)
    out = tmp_path / "run"
    monkeypatch.delenv("CROWDMPC_DATA", raising=False)
    common = ["--batch-size", "4", "--limit-batches", "1", "--out", str(out)]
    assert _train("--data-dir", str(prepared), "--epochs", "1", *common) == 0
    capsys.readouterr()

    monkeypatch.setenv("CROWDMPC_DATA", str(tmp_path / "data"))  # the raw data, not yet in the cache
    assert _train("--epochs", "2", "--out", str(out), "--resume") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert f"trained on the prepared data in {prepared.resolve()}" in err
    assert f"$CROWDMPC_DATA {tmp_path / 'data'}" in err and f"--data-dir {prepared.resolve()}" in err

    assert not (Path(os.environ["CROWDMPC_CACHE"]) / "prepared").exists()  # nothing was prepared

    # a --data-dir typed that gives other files: the same line, naming the option
    assert _train("--data-dir", str(tmp_path / "data"), "--epochs", "2", "--out", str(out), "--resume") == 2
    assert f"--data-dir {tmp_path / 'data'} gives" in capsys.readouterr().err
    # the run's data directory, by the environment or typed: the resume goes on
    monkeypatch.setenv("CROWDMPC_DATA", str(prepared))
    assert _train("--epochs", "2", "--out", str(out), "--resume") == 0
