"""Two sets of weights under one zoo name (``zoo add --replace``) are two predictors: their recordings were
one set-up in `review`, pooled into one aggregate, and a rerun of a seed with the new weights replaced the old
weights' recording without a word. The weights' sha256 is part of what identifies a run's recordings."""

from __future__ import annotations

import json

import pytest

from pipelines.cli import main
from pipelines.errors import PipelineError
from tests.pipelines.mcap_episode import record_episode

OLD, NEW = "86" * 32, "ee" * 32


def test_review_keeps_two_weights_of_one_name_apart(tmp_path, capsys):
    record_episode(tmp_path, seed=1, steps=3, predictor_sha256=OLD)
    record_episode(tmp_path, seed=2, steps=3, predictor_sha256=NEW)
    assert main(["review", str(tmp_path), "--json", str(tmp_path / "review.json")]) == 0
    groups = json.loads((tmp_path / "review.json").read_text())["groups"]
    assert len(groups) == 2 and all(len(g["files"]) == 1 for g in groups)
    assert sorted(g["settings"]["predictor_sha256"] for g in groups) == [OLD, NEW]


def test_a_recording_of_other_weights_is_not_replaced(tmp_path):
    record_episode(tmp_path, seed=1, steps=3, predictor_sha256=OLD)
    record_episode(tmp_path, seed=1, steps=3, predictor_sha256=OLD)  # a rerun of its own run replaces it
    with pytest.raises(PipelineError, match=r"it holds another run's episode \(.*predictor_sha256"):
        record_episode(tmp_path, seed=1, steps=3, predictor_sha256=NEW)
