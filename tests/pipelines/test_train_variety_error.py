"""``crowdmpc train --variety-error``: social_gan's best-of-k loss on the distance (the default, every shipped
GAN's) or on the squared error (Social GAN's); refused in one line when unknown or for a net without that
loss, recorded wherever the run's settings are, and resumed as the run's (a run from before the option
trained on the distance)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipelines.cli import main
from tests.predictors.samples import write_walk_file


@pytest.fixture(autouse=True)
def _private_dirs(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))
    monkeypatch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path_factory.mktemp("shipped")))


def _args(data: Path, out: Path, epochs: int, *extra: str, model: str = "social_gan") -> list[str]:
    files = ["--train", str(data), "--val", str(data), "--test", str(data)]
    args = ["train", "--model", model, *files, "--epochs", str(epochs), "--limit-batches", "1"]
    return [*args, "--out", str(out), "--no-progress", *extra]


def _one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err.rstrip("\n")


def test_an_unknown_variety_error_is_refused_in_one_line(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["train", "--model", "social_gan", "--variety-error", "mse"])
    assert stop.value.code == 2
    assert _one_line(capsys) == (
        "crowdmpc train: error: argument --variety-error: invalid choice: 'mse' (choose from 'distance', "
        "'squared'); see 'crowdmpc train --help'"
    )


def test_the_command_offers_the_errors_the_loss_knows():
    """The CLI lists them without importing torch (predictors.nets.losses does); no parser default, so that
    a resume can tell it left out (train_resume.RUN_OPTIONS holds the default)."""
    import argparse

    from pipelines.commands import train
    from pipelines.commands.train_resume import RUN_OPTIONS
    from predictors.nets.losses import VARIETY_ERRORS

    parser = argparse.ArgumentParser()
    train.register(parser.add_subparsers())
    (command,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    (option,) = [a for a in command.choices["train"]._actions if a.dest == "variety_error"]
    assert tuple(option.choices) == VARIETY_ERRORS and option.default is None
    assert RUN_OPTIONS["variety_error"] == "distance"


def test_a_variety_error_for_a_net_without_the_loss_is_refused(tmp_path, capsys):
    """vanilla_lstm trains on L2 or its Gaussian: the option would be recorded and ignored."""
    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    assert main(_args(data, out, 1, "--variety-error", "squared", model="vanilla_lstm")) == 2
    assert _one_line(capsys) == (
        "crowdmpc train: error: --variety-error does not apply to vanilla_lstm (only a GAN trains on a "
        "best-of-k variety loss)"
    )
    assert not out.exists()


def test_the_variety_error_is_recorded_and_resumed_as_the_runs(tmp_path, capsys):
    import torch

    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    assert main(_args(data, out, 1, "--variety-error", "squared")) == 0
    assert json.loads((out / "train_settings.json").read_text())["variety_error"] == "squared"
    last = torch.load(out / "checkpoints" / "last.ckpt", weights_only=False)
    assert last["hyper_parameters"]["optim_config"]["variety_error"] == "squared"
    training = json.loads((out / "social_gan_custom.json").read_text())["training"]
    assert training["optim"]["variety_error"] == "squared"
    capsys.readouterr()
    assert main(_args(data, out, 2, "--variety-error", "distance", "--resume")) == 2
    assert _one_line(capsys) == (
        f"crowdmpc train: error: --resume: {out} was started with other settings (variety_error: run "
        '"squared", now "distance"); resume with the run\'s settings (only --epochs may change) or start a '
        "new run with another --out"
    )
    assert main(_args(data, out, 2, "--resume")) == 0
    assert f"--resume: {out} goes on with the run's variety_error squared\n" in capsys.readouterr().err
    last = torch.load(out / "checkpoints" / "last.ckpt", weights_only=False)
    assert last["epoch"] == 1 and last["hyper_parameters"]["optim_config"]["variety_error"] == "squared"


def test_a_run_from_before_the_option_resumes_on_the_distance(tmp_path, capsys):
    """Its train_settings.json and last.ckpt name no variety error: it trained on the distance, which a
    resume goes on with, and refuses the squared error for. A damaged record is named."""
    import torch

    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    assert main(_args(data, out, 1)) == 0
    settings = out / "train_settings.json"
    recorded = json.loads(settings.read_text())
    assert recorded["variety_error"] == "distance"
    del recorded["variety_error"]
    settings.write_text(json.dumps(recorded))
    last = out / "checkpoints" / "last.ckpt"
    checkpoint = torch.load(last, weights_only=False)
    del checkpoint["hyper_parameters"]["optim_config"]["variety_error"]
    torch.save(checkpoint, last)
    capsys.readouterr()
    assert main(_args(data, out, 2, "--variety-error", "squared", "--resume")) == 2
    assert 'variety_error: run "distance", now "squared"' in _one_line(capsys)
    assert main(_args(data, out, 2, "--resume")) == 0
    assert "the run's variety_error" not in capsys.readouterr().err
    assert torch.load(last, weights_only=False)["epoch"] == 1

    settings.write_text(json.dumps({**recorded, "variety_error": "cubed"}))
    assert main(_args(data, out, 3, "--resume")) == 2
    assert _one_line(capsys) == (
        "crowdmpc train: error: --resume: --variety-error must be one of distance, squared, got 'cubed', "
        f"taken from {settings}; the file is damaged"
    )
