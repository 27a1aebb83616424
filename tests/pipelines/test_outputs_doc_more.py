"""docs/outputs.md against what evaluate, train, calibrate and cache info write: every key of their files
is named there (the sections were added after tests/pipelines/test_outputs_doc.py covered the others)."""

from __future__ import annotations

import json
from pathlib import Path

from pipelines.cli import main
from tests.pipelines.test_outputs_doc import _documented, _strict, _undocumented
from tests.predictors.samples import write_crowds


def _keys(value, depth: int) -> list[str]:
    """The keys of ``value`` down to ``depth`` levels of objects (lists of objects looked into)."""
    if depth == 0:
        return []
    if isinstance(value, list):
        return [k for item in value for k in _keys(item, depth)]
    if not isinstance(value, dict):
        return []
    return [*value, *(k for v in value.values() for k in _keys(v, depth - 1))]


def test_every_evaluate_and_cache_info_field_is_documented(tmp_path):
    data = write_crowds(tmp_path / "crowds.ndjson")
    scores = tmp_path / "scores.json"
    assert (
        main(["evaluate", "--predictor", "constant_velocity", "--test", str(data), "--json", str(scores)])
        == 0
    )
    result = _strict(scores.read_text())
    doc = _documented()
    assert _undocumented([*result, *result["overall"]], doc) == []
    assert main(["cache", "info", "--json", str(tmp_path / "cache.json")]) == 0
    assert _undocumented(_strict((tmp_path / "cache.json").read_text()), doc) == []


def test_every_file_and_key_train_writes_is_documented(tmp_path):
    data = str(write_crowds(tmp_path / "crowds.ndjson"))
    out = tmp_path / "run"
    argv = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--epochs", "1"]
    assert main([*argv, "--batch-size", "2", "--no-progress", "--out", str(out)]) == 0
    doc = _documented()
    settings = _strict((out / "train_settings.json").read_text())
    assert _undocumented([k for k in settings if k != "code"], doc) == []
    config = _strict((out / "vanilla_lstm_custom.json").read_text())
    assert _undocumented([*config, *config["training"], *config["training"]["optim"]], doc) == []
    metrics = _strict((out / "vanilla_lstm_custom.metrics.json").read_text())
    assert _undocumented([*metrics, *metrics["training"]], doc) == []
    columns = (next(out.glob("csv/version_*/metrics.csv"))).read_text().splitlines()[0].split(",")
    assert _undocumented(columns, doc) == []
    files = {p.name.replace("vanilla_lstm_custom", "NAME") for p in out.iterdir() if p.is_file()}
    assert _undocumented(files, doc) == []


def test_every_calibrate_field_is_documented(tmp_path):
    report = tmp_path / "calibration.json"
    argv = ["calibrate", "--predictor", "constant_velocity", "--source", "closed-loop", "--episodes", "1"]
    argv += ["--humans", "2", "--holdout", "--dry-run", "--no-progress", "--json", str(report)]
    assert main(argv) == 0
    written = _strict(report.read_text())
    (block,) = written["blocks"]
    assert _undocumented([*written, *block, *block["details"]], _documented()) == []
    assert json.loads(Path(report).read_text(encoding="utf-8"))["holdout_margins"] == "none"
