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


def test_metrics_csv_survives_a_failure_while_a_new_column_rewrites_it(tmp_path, capsys, monkeypatch):
    """Lightning rewrote metrics.csv in place (truncated, then written) whenever a column first came: at the
    fifth step, and at the first epoch's end for the validation metrics and epoch_time_s. A kill -9 or a
    full disk in that rewrite lost every row before; now the rewrite is a new file renamed over the old,
    and a failure in it leaves the old file whole (and a run's file as Lightning wrote it)."""
    import csv
    import errno

    walk = str(write_walk_file(tmp_path / "walk.ndjson"))
    argv = ["train", "--model", "vanilla_lstm", "--train", walk, "--val", walk, "--epochs", "3"]
    argv += ["--batch-size", "1", "--no-progress"]  # 2 steps an epoch: train_loss first comes in the third
    code, _, err = run_cli(capsys, *argv, "--out", str(tmp_path / "whole"))
    assert code == 0, err
    (whole,) = (tmp_path / "whole" / "csv").glob("version_*/metrics.csv")
    rows = list(csv.DictReader(whole.open(newline="")))
    assert [r["step"] for r in rows[:2]] == ["0", "1"] and len(rows) == 10, whole.read_text()
    assert list(rows[0]) == [
        "epoch", "epoch_time_s", "lr-Adam", "step", "train_loss", "train_loss_epoch", "val_ade", "val_fde",
        "val_loss",
    ]  # fmt: skip
    headers = []
    writeheader = csv.DictWriter.writeheader

    def full_disk(self):  # the file's creation, its first rewrite (val_*), then the disk is full
        headers.append(list(self.fieldnames))
        if len(headers) == 3:
            raise OSError(errno.ENOSPC, "No space left on device")
        return writeheader(self)

    monkeypatch.setattr(csv.DictWriter, "writeheader", full_disk)
    code, _, err = run_cli(capsys, *argv, "--out", str(tmp_path / "full"))
    assert code != 0 and "epoch_time_s" in headers[2], headers
    (kept,) = (tmp_path / "full" / "csv").glob("version_*/metrics.csv")
    # the rows of the first epoch, lr-Adam's at step 0 and the validation's at step 1, are still there
    assert [r.get("step") for r in csv.DictReader(kept.open(newline=""))][:2] == ["0", "1"], kept.read_text()


def test_a_lightning_writer_without_the_fields_read_gets_lightnings_own_save(tmp_path, monkeypatch):
    """WholeCSVLogger reads fields of Lightning's private _ExperimentWriter; a release that renamed them would
    have failed every training at its first save. Such a writer now gets Lightning's save as it is."""
    from lightning.pytorch.loggers import CSVLogger

    from pipelines.commands.train_checkpoint import WholeCSVLogger

    saved = []
    monkeypatch.setattr(CSVLogger, "save", lambda self: saved.append(self))
    monkeypatch.setattr(WholeCSVLogger, "experiment", property(lambda self: object()))  # no fields at all
    logger = WholeCSVLogger(str(tmp_path))
    logger.save()
    assert saved == [logger]
