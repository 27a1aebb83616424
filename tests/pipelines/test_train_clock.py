"""A resumed training run's wall time counts its earlier parts (``TrainingClock``, kept in last.ckpt): its
NAME.metrics.json said only how long the last part took."""

import json

import torch

from pipelines.cli import main
from tests.predictors.samples import write_walk_file


def _train(tmp_path, epochs: int, *extra: str) -> int:
    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    args = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--no-progress"]
    return main([*args, "--epochs", str(epochs), "--out", str(tmp_path / "run"), *extra])


def _wall_time(tmp_path) -> float:
    return json.loads((tmp_path / "run" / "vanilla_lstm_custom.metrics.json").read_text())["training"][
        "wall_time_s"
    ]


def test_a_resumed_runs_wall_time_counts_the_parts_before(tmp_path):
    assert _train(tmp_path, 1) == 0
    last = tmp_path / "run" / "checkpoints" / "last.ckpt"
    checkpoint = torch.load(last, weights_only=True)
    first = checkpoint["callbacks"]["TrainingClock"]["seconds"]
    assert 0 < first <= _wall_time(tmp_path) + 0.05  # up to its last checkpoint, within the fit
    # as if the first part had taken 1000 s: the resume's wall time is theirs and its own
    checkpoint["callbacks"]["TrainingClock"]["seconds"] = 1000.0
    torch.save(checkpoint, last)
    assert _train(tmp_path, 2, "--resume") == 0
    # the file's figure is rounded to 0.1 s, and an epoch of this walk takes 0.02 s on a fast host: the
    # checkpoint's unrounded clock says that the resume's own time was added
    assert 1000.0 <= _wall_time(tmp_path) < 1000.0 + 120
    assert torch.load(last, weights_only=True)["callbacks"]["TrainingClock"]["seconds"] > 1000.0


def test_a_last_checkpoint_from_before_the_clock_counts_from_the_resume(tmp_path):
    assert _train(tmp_path, 1) == 0
    last = tmp_path / "run" / "checkpoints" / "last.ckpt"
    checkpoint = torch.load(last, weights_only=True)
    checkpoint["callbacks"]["TrainingClock"] = {"seconds": "damaged"}  # a value it cannot take: ignored
    torch.save(checkpoint, last)
    assert _train(tmp_path, 2, "--resume") == 0
    resumed = _wall_time(tmp_path)
    del checkpoint["callbacks"]["TrainingClock"]
    torch.save(checkpoint, last)
    assert _train(tmp_path, 3, "--resume") == 0
    assert 0 <= resumed < 120 and 0 <= _wall_time(tmp_path) < 120  # rounded to 0.1 s: 0.0 on a fast host
    assert 0 < torch.load(last, weights_only=True)["callbacks"]["TrainingClock"]["seconds"] < 120
