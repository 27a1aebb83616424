"""``crowdmpc train --batching``: refused in one line when unknown, recorded wherever the run's settings are,
and resumed as an uninterrupted run batches (or refused when the resume asks for other batching)."""

from __future__ import annotations

import json

import pytest

from pipelines.cli import main
from tests.predictors.samples import write_crowds


def test_an_unknown_batching_is_refused_in_one_line(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["train", "--model", "social_lstm", "--batching", "size"])
    assert stop.value.code == 2
    assert capsys.readouterr().err == (
        "crowdmpc train: error: argument --batching: invalid choice: 'size' (choose from 'shuffled', "
        "'by_size'); see 'crowdmpc train --help'\n"
    )


def test_the_command_offers_the_batchings_the_data_module_knows():
    """The CLI lists them without importing torch (predictors.data.batching does)."""
    import argparse

    from pipelines.commands import train
    from predictors.data.batching import BATCHINGS

    parser = argparse.ArgumentParser()
    train.register(parser.add_subparsers())
    (command,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    (option,) = [a for a in command.choices["train"]._actions if a.dest == "batching"]
    # no parser default, so that a resume can tell it left out (train_resume.RUN_OPTIONS holds the default)
    from pipelines.commands.train_resume import RUN_OPTIONS

    assert tuple(option.choices) == BATCHINGS and option.default is None
    assert RUN_OPTIONS["batching"] == "shuffled"


def _args(data: str, out, *extra: str) -> list[str]:
    files = ["--train", data, "--val", data, "--test", data]
    args = ["train", "--model", "vanilla_lstm", *files, "--batch-size", "2", "--step-size", "1"]
    return [*args, "--seed", "3", "--out", str(out), "--no-progress", *extra]


@pytest.mark.parametrize("batching", ["shuffled", "by_size"])
def test_the_batching_is_recorded_with_the_run(tmp_path, batching):
    import torch

    data = str(write_crowds(tmp_path / "crowds.ndjson"))
    out = tmp_path / "run"
    assert main(_args(data, out, "--epochs", "1", "--batching", batching)) == 0
    assert json.loads((out / "train_settings.json").read_text())["batching"] == batching
    assert json.loads((out / "vanilla_lstm_custom.json").read_text())["training"]["batching"] == batching
    metrics = json.loads((out / "vanilla_lstm_custom.metrics.json").read_text())
    assert metrics["training"]["batching"] == batching
    last = torch.load(out / "checkpoints" / "last.ckpt", weights_only=False)
    assert last["datamodule_hyper_parameters"]["batching"] == batching


def test_a_resumed_by_size_run_ends_where_an_uninterrupted_one_does(tmp_path):
    """One epoch then --resume to three equals three epochs straight, weight for weight: Lightning sets the
    epoch of the batch sampler's EpochShuffle, which alone decides its batches. And by_size trains other
    weights than shuffled from the same seed (the scenes' sizes differ: 3, 1, 2, 3, 4 agents)."""
    import torch

    data = str(write_crowds(tmp_path / "crowds.ndjson"))

    def train(out: str, epochs: int, *extra: str) -> dict:
        assert main(_args(data, tmp_path / out, "--epochs", str(epochs), *extra)) == 0
        return torch.load(tmp_path / out / "checkpoints" / "last.ckpt", weights_only=False)["state_dict"]

    straight = train("straight", 3, "--batching", "by_size")
    train("resumed", 1, "--batching", "by_size")
    resumed = train("resumed", 3, "--batching", "by_size", "--resume")
    assert straight.keys() == resumed.keys()
    assert all(torch.equal(straight[k], resumed[k]) for k in straight)
    shuffled = train("shuffled", 3)
    assert not all(torch.equal(straight[k], shuffled[k]) for k in straight)


def test_a_resume_goes_on_with_the_runs_batching_and_refuses_another(tmp_path, capsys):
    """As for any other setting: left out, the run's batching (it was refused: "shuffled" had to be typed
    away by typing by_size again); typed, the run's or none. A run from before --batching (no record in its
    settings file nor in its last.ckpt) batched as "shuffled": resumed by_size, it is refused too."""
    import torch

    data = str(write_crowds(tmp_path / "crowds.ndjson"))
    out = tmp_path / "run"
    assert main(_args(data, out, "--epochs", "1", "--batching", "by_size")) == 0
    capsys.readouterr()
    assert main(_args(data, out, "--epochs", "2", "--batching", "shuffled", "--resume")) == 2
    assert 'batching: run "by_size", now "shuffled"' in capsys.readouterr().err
    assert main(_args(data, out, "--epochs", "2", "--resume")) == 0
    assert f"--resume: {out} goes on with the run's batching by_size\n" in capsys.readouterr().err
    checkpoint = torch.load(out / "checkpoints" / "last.ckpt", weights_only=False)
    assert checkpoint["datamodule_hyper_parameters"]["batching"] == "by_size" and checkpoint["epoch"] == 1

    old = tmp_path / "old"
    assert main(_args(data, old, "--epochs", "1")) == 0
    settings = old / "train_settings.json"
    recorded = json.loads(settings.read_text())
    del recorded["batching"]
    settings.write_text(json.dumps(recorded))
    last = old / "checkpoints" / "last.ckpt"
    checkpoint = torch.load(last, weights_only=False)
    del checkpoint["datamodule_hyper_parameters"]["batching"]
    torch.save(checkpoint, last)
    capsys.readouterr()
    assert main(_args(data, old, "--epochs", "2", "--batching", "by_size", "--resume")) == 2
    assert 'batching: checkpoint "shuffled", now "by_size"' in capsys.readouterr().err
    assert main(_args(data, old, "--epochs", "2", "--resume")) == 0


def test_a_resume_of_only_epochs_goes_on_with_every_setting_of_the_run(tmp_path, capsys):
    """A run at batch 2, seed 5, by_size, lr 2e-3, decay every epoch and hidden size 16, resumed with
    nothing but its files, --out and --epochs, was refused (the defaults 8, 0, shuffled, 1e-3, 10 and 32
    against the run's); it goes on with each of the run's now, and a typed --batch-size 3 is still refused,
    naming it."""
    import torch

    data = str(write_crowds(tmp_path / "crowds.ndjson"))
    out = tmp_path / "run"
    files = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--test", data]
    lean = [*files, "--out", str(out), "--no-progress"]
    run = ["--batch-size", "2", "--seed", "5", "--batching", "by_size", "--lr", "0.002", "--step-size", "1"]
    assert main([*lean, *run, "--hidden-dim", "16", "--epochs", "1"]) == 0
    capsys.readouterr()
    assert main([*lean, "--epochs", "2", "--resume"]) == 0
    err = capsys.readouterr().err
    assert (
        f"--resume: {out} goes on with the run's lr 0.002, step_size 1, batch_size 2, batching by_size, "
        "seed 5, its net config\n" in err
    )
    checkpoint = torch.load(out / "checkpoints" / "last.ckpt", weights_only=False)
    assert checkpoint["epoch"] == 1  # two epochs finished: the resume trained one
    data_module = checkpoint["datamodule_hyper_parameters"]
    assert (data_module["batch_size"], data_module["seed"], data_module["batching"]) == (2, 5, "by_size")
    hyper = checkpoint["hyper_parameters"]
    assert (hyper["optim_config"]["lr"], hyper["optim_config"]["step_size"]) == (0.002, 1)
    assert hyper["net_config"]["hidden_dim"] == 16
    training = json.loads((out / "vanilla_lstm_custom.json").read_text())["training"]
    assert (training["batch_size"], training["seed"], training["batching"]) == (2, 5, "by_size")

    assert main([*lean, "--epochs", "3", "--batch-size", "3", "--resume"]) == 2
    err = capsys.readouterr().err
    assert f"--resume: {out} was started with other settings (batch_size: run 2, now 3); " in err
    assert err.count("\n") == 1 and "Traceback" not in err
