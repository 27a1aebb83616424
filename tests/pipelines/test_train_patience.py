"""`crowdmpc train --patience N`: Lightning's EarlyStopping on validation ADE, recorded with the weights, its
count carried across a resume as Lightning keeps it in last.ckpt, and a finished run it stopped never
trained on. A learning rate of 1e-12 leaves float32 weights as they are: validation ADE never improves after
the first epoch, so the stop comes after exactly 1 + N epochs."""

import json

import pytest
import torch

from pipelines.cli import main
from tests.cli_calls import one_line, run_cli
from tests.predictors.samples import write_walk_file

FROZEN = ["--lr", "1e-12"]


def _train(tmp_path, *extra: str) -> list[str]:
    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    args = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--no-progress"]
    return [*args, "--out", str(tmp_path / "run"), *extra]


def _training(tmp_path) -> dict:
    return json.loads((tmp_path / "run" / "vanilla_lstm_custom.json").read_text())["training"]


def _epochs_done(tmp_path) -> int:
    last = torch.load(tmp_path / "run" / "checkpoints" / "last.ckpt", weights_only=True)
    return int(last["epoch"]) + 1


def test_the_fit_stops_once_validation_ade_has_not_improved_for_n_epochs(tmp_path, capsys):
    code, out, _ = run_cli(capsys, *_train(tmp_path, "--epochs", "6", "--patience", "2", *FROZEN))
    assert code == 0 and "stopped early after 3 of 6 epochs" in out and "(--patience 2)" in out
    assert _epochs_done(tmp_path) == 3
    assert {"patience": 2, "stopped_early_after": 3}.items() <= _training(tmp_path).items()
    metrics = json.loads((tmp_path / "run" / "vanilla_lstm_custom.metrics.json").read_text())
    assert metrics["training"]["stopped_early_after"] == 3


def test_a_fit_the_patience_never_stopped_records_the_patience_alone(tmp_path, capsys):
    code, out, _ = run_cli(capsys, *_train(tmp_path, "--epochs", "2", "--patience", "5"))
    training = _training(tmp_path)
    assert code == 0 and "stopped early" not in out and _epochs_done(tmp_path) == 2
    assert training["patience"] == 5 and "stopped_early_after" not in training


def test_without_patience_the_record_is_as_before(tmp_path):
    assert main(_train(tmp_path, "--epochs", "1")) == 0
    assert not {"patience", "stopped_early_after"} & _training(tmp_path).keys()


def test_a_resume_counts_on_from_where_the_run_was(tmp_path, capsys):
    """Two epochs, one without a gain; the resume to six stops after the third, as one run of six does
    (a count started afresh would stop after the fifth)."""
    assert main(_train(tmp_path, "--epochs", "2", "--patience", "2", *FROZEN)) == 0
    code, out, err = run_cli(capsys, *_train(tmp_path, "--resume", "--epochs", "6"))
    assert code == 0 and "goes on with the run's" in err and "patience 2" in err
    assert "stopped early after 3 of 6 epochs" in out and _epochs_done(tmp_path) == 3


def test_a_finished_run_its_patience_stopped_is_not_resumed(tmp_path, capsys):
    assert main(_train(tmp_path, "--epochs", "6", "--patience", "1", *FROZEN)) == 0
    code, _, err = run_cli(capsys, *_train(tmp_path, "--resume", "--epochs", "8"))
    assert code == 2
    refusal = "stopped early after 2 epochs (validation ADE had not improved in the last 1, its --patience)"
    assert refusal + ": it is finished; start a new run with another --out" in one_line(err)


def test_the_patience_is_the_runs_on_a_resume(tmp_path, capsys):
    assert main(_train(tmp_path, "--epochs", "1", "--patience", "3")) == 0
    code, _, err = run_cli(capsys, *_train(tmp_path, "--resume", "--epochs", "2", "--patience", "4"))
    assert code == 2 and "patience: run 3, now 4" in one_line(err)


@pytest.mark.parametrize("value", ["0", "-1", "100001"])
def test_a_patience_out_of_bounds_is_refused(tmp_path, capsys, value):
    code, _, err = run_cli(capsys, *_train(tmp_path, "--patience", value))
    assert code == 2 and f"--patience must be in 1..100000, got {value}" in one_line(err)


def test_a_stopped_run_cut_before_its_outputs_is_finished_by_its_resume_not_trained_on(tmp_path, capsys):
    """As a Ctrl-C during the final evaluation leaves it (no metrics file, or a damaged one): Lightning checks
    the stop at an epoch's end, and trained one epoch past it, recorded as the run's."""
    assert main(_train(tmp_path, "--epochs", "6", "--patience", "2", *FROZEN)) == 0
    metrics = tmp_path / "run" / "vanilla_lstm_custom.metrics.json"
    for cut in (None, "[]"):
        metrics.unlink() if cut is None else metrics.write_text(cut)
        code, out, err = run_cli(capsys, *_train(tmp_path, "--resume"))
        assert code == 0 and "stopped early after 3 of 6 epochs" in out and _epochs_done(tmp_path) == 3
        assert "stopped after 3 epochs, its --patience run out; this resume trains no epoch and writes its " \
            "outputs" in err  # fmt: skip
        assert _training(tmp_path)["stopped_early_after"] == 3
    metrics.unlink()
    code, _, err = run_cli(capsys, *_train(tmp_path, "--resume", "--epochs", "2"))
    assert code == 2 and one_line(err).endswith(
        "stopped early after 3 epochs (its --patience); --epochs 2 is fewer: resume it without --epochs to "
        "write what its stop left out"
    )


def test_a_stop_at_the_last_epoch_is_no_early_stop(tmp_path, capsys):
    code, out, _ = run_cli(capsys, *_train(tmp_path, "--epochs", "3", "--patience", "2", *FROZEN))
    assert code == 0 and "stopped early" not in out and "stopped_early_after" not in _training(tmp_path)
    # finished: the same count again trains none, as for any run
    code, _, err = run_cli(capsys, *_train(tmp_path, "--resume", "--epochs", "3"))
    assert code == 2 and "has trained 3 epochs already" in one_line(err)
    # more epochs: its count had run out, so it ends where a run of 6 ends, training none
    code, out, err = run_cli(capsys, *_train(tmp_path, "--resume", "--epochs", "6"))
    assert code == 0 and "its --patience run out; this resume trains no epoch" in err
    assert "stopped early after 3 of 6 epochs" in out and _epochs_done(tmp_path) == 3


def test_a_run_from_before_patience_was_kept_ran_without_one(tmp_path, capsys):
    assert main(_train(tmp_path, "--epochs", "1")) == 0
    settings = tmp_path / "run" / "train_settings.json"
    settings.write_text(
        json.dumps({k: v for k, v in json.loads(settings.read_text()).items() if k != "patience"})
    )
    code, _, err = run_cli(capsys, *_train(tmp_path, "--resume", "--epochs", "2", "--patience", "1"))
    assert code == 2 and "patience: run null, now 1" in one_line(err)


def test_a_diverged_fit_is_said_as_such_not_as_a_loss_of_patience(tmp_path, capsys):
    model = "tests.plugins.broken_nets:NaNFromItsThirdStep"
    argv = ["--plugin", model, *_train(tmp_path, "--epochs", "5", "--patience", "3")]
    argv[argv.index("vanilla_lstm")] = model
    code, out, err = run_cli(capsys, *argv)
    assert code == 0 and "training stopped: the training loss was nan in epoch 2" in err
    assert "stopped early" not in out
    training = json.loads((tmp_path / "run" / "na_nfrom_its_third_step_custom.json").read_text())["training"]
    assert training["patience"] == 3 and "stopped_early_after" not in training
