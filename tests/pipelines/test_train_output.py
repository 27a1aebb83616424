"""What `crowdmpc train` writes where: its results on stdout, Lightning's progress bars on stderr (they were
drawn on stdout, carriage returns and cursor-up escapes among a script's results)."""

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
