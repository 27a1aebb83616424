"""A resume restores more than the weights: the optimizers' and schedulers' states, torch's random state and
the epoch. A last.ckpt edited by hand in any of them ended `train --resume` in a 30-50 line traceback from
Lightning or torch; it is one line naming what is damaged, and the run is left as it was."""

from __future__ import annotations

import shutil

import pytest
import torch

from pipelines.cli import main
from tests.predictors.samples import write_walk_file


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("run")
    data = str(write_walk_file(root / "walk.ndjson"))
    args = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--no-progress"]
    assert main([*args, "--out", str(root / "run"), "--epochs", "1"]) == 0
    return root, args


def _damaged(checkpoint: dict, how: str) -> None:
    if how == "no optimizer":
        del checkpoint["optimizer_states"]
    elif how == "no parameter groups":
        checkpoint["optimizer_states"] = [{"state": {}, "param_groups": []}]
    elif how == "random state of floats":
        checkpoint["crowdmpc_torch_rng"] = torch.zeros(3)
    elif how == "negative epoch":
        checkpoint["epoch"] = -5
    elif how == "scheduler of nothing":
        checkpoint["lr_schedulers"] = [{"bogus": 1}]


@pytest.mark.parametrize(
    ("how", "said"),
    [
        ("no optimizer", "optimizer_states: 1 expected, the file holds none"),
        ("no parameter groups", "optimizer_states: ValueError: loaded state dict has a different number of "),
        ("random state of floats", "crowdmpc_torch_rng is not torch's random state"),
        ("negative epoch", "epoch -5, not a count from 0"),
        ("scheduler of nothing", "lr_schedulers: a state without the keys ['base_lrs', 'last_epoch']"),
    ],
)
def test_a_damaged_training_state_is_one_line_and_the_run_is_kept(trained, tmp_path, capsys, how, said):
    root, args = trained
    run = tmp_path / "run"
    shutil.copytree(root / "run", run)
    last = run / "checkpoints" / "last.ckpt"
    checkpoint = torch.load(last, weights_only=True)
    _damaged(checkpoint, how)
    torch.save(checkpoint, last)
    weights = (run / "vanilla_lstm_custom.pt").read_bytes()
    capsys.readouterr()
    assert main([*args, "--out", str(run), "--resume", "--epochs", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"crowdmpc train: error: --resume: {last} is damaged ({said}")
    assert (run / "vanilla_lstm_custom.pt").read_bytes() == weights


def test_a_whole_run_still_resumes(trained, tmp_path):
    root, args = trained
    shutil.copytree(root / "run", tmp_path / "run")
    assert main([*args, "--out", str(tmp_path / "run"), "--resume", "--epochs", "2"]) == 0
    assert torch.load(tmp_path / "run" / "checkpoints" / "last.ckpt", weights_only=True)["epoch"] == 1
