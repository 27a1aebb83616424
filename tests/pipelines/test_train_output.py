"""What `crowdmpc train` writes where: its results on stdout, Lightning's progress bars on stderr (they were
drawn on stdout, carriage returns and cursor-up escapes among a script's results); nothing of a net refused
as a predictor once trained."""

from __future__ import annotations

import sys

from tests.cli_calls import run_cli
from tests.predictors.samples import write_walk_file


def test_train_draws_its_progress_bars_on_stderr(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)  # a terminal's (elsewhere: a line an epoch)
    walk = str(write_walk_file(tmp_path / "walk.ndjson"))
    argv = ["train", "--model", "vanilla_lstm", "--train", walk, "--val", walk, "--epochs", "1"]
    code, out, err = run_cli(capsys, *argv, "--out", str(tmp_path / "run"))
    assert code == 0, err
    assert "\r" not in out and "\x1b[" not in out and out.startswith("vanilla_lstm_custom: best checkpoint")
    assert "Epoch 0" in err  # the bar, where every command's progress goes


def test_a_trained_net_refused_as_a_predictor_leaves_no_weights_in_out(tmp_path, capsys):
    """A net NaN in eval mode alone trains all its epochs; its NAME.pt and NAME.json were written, then
    refused on reading back, and lay in --out as a trained model's for `zoo add` to take."""
    model = "tests.plugins.broken_nets:NaNWhenEvaluated"
    walk = str(write_walk_file(tmp_path / "walk.ndjson"))
    argv = ["--plugin", model, "train", "--model", model, "--train", walk, "--val", walk, "--epochs", "1"]
    code, _, err = run_cli(capsys, *argv, "--no-progress", "--out", str(tmp_path / "run"))
    line = err.strip().splitlines()[-1]  # Lightning's logging precedes it
    assert code == 2 and "na_nwhen_evaluated_custom.pt and its .json were not written" in line
    assert line.startswith("crowdmpc train: error: ") and "encode's out holds NaN or inf" in line
    left = {p.name for p in (tmp_path / "run").iterdir()}
    assert left == {"checkpoints", "csv", "tensorboard", "train_settings.json"}
