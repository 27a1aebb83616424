"""`crowdmpc train` given Lightning's names: the one-line error points at crowdmpc's own option, or says why
there is none (pipelines/lightning_names.py)."""

import pytest

from pipelines.cli import main

EPOCHS = "is Lightning's max_epochs: crowdmpc train's is --epochs"
NO_ACCELERATOR = "crowdmpc train has none: it trains on the CPU in one thread"


def _error(capsys, argv: list[str]) -> str:
    with pytest.raises(SystemExit) as done:
        main(argv)
    assert done.value.code == 2
    (line,) = capsys.readouterr().err.splitlines()
    return line


@pytest.mark.parametrize("typed", ["--max-epochs", "--max_epochs", "--trainer.max_epochs"])
def test_lightnings_max_epochs_points_at_epochs(capsys, typed):
    """`crowdmpc train --max-epochs 3` was "unrecognized arguments: --max-epochs 3", no word of --epochs."""
    line = _error(capsys, ["train", "--model", "social_lstm", typed, "3"])
    assert line == (
        f"crowdmpc train: error: unrecognized arguments: {typed} 3 ({typed} {EPOCHS}); "
        "see 'crowdmpc train --help'"
    )
    # written with "=", and before --model is given (argparse asks for --model first)
    assert f"({typed} {EPOCHS})" in _error(capsys, ["train", f"{typed}=3", "--model", "social_lstm"])
    assert _error(capsys, ["train", typed, "3"]).startswith(
        f"crowdmpc train: error: the following arguments are required: --model ({typed} {EPOCHS}); "
    )


def test_an_accelerator_or_precision_is_said_to_be_absent_on_purpose(capsys):
    line = _error(capsys, ["train", "--model", "social_lstm", "--accelerator", "gpu", "--precision", "16"])
    assert f"(--accelerator, --precision: {NO_ACCELERATOR}" in line
    assert "a lightning.Trainer of your own (docs/extending.md)" in line


def test_other_lightning_names_with_an_equivalent(capsys):
    line = _error(
        capsys, ["train", "--model", "social_lstm", "--batch_size", "4", "--limit_train_batches", "2"]
    )
    assert "--batch_size is Lightning's batch_size: crowdmpc train's is --batch-size" in line
    assert (
        "--limit_train_batches is Lightning's limit_train_batches: crowdmpc train's is --limit-batches"
        in line
    )


@pytest.mark.parametrize(
    "argv",
    [
        ["train", "--model", "social_lstm", "--bogus", "3"],  # no Lightning name
        ["train", "--model", "social_lstm", "--name=--max-epochs", "--bogus"],  # an option's value
        ["train", "--model", "social_lstm", "--batch-size", "4", "--bogus"],  # crowdmpc's own name
        ["simulate", "--max-epochs", "3"],  # another command trains nothing
        ["--plugin", "no_such_module:Net", "train", "--max-epochs", "3"],  # the top level's own error
    ],
)
def test_no_hint_where_no_lightning_name_is_refused_by_train(capsys, argv):
    line = _error(capsys, argv)
    assert "Lightning's" not in line and "crowdmpc train has none" not in line
