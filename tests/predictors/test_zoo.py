"""The zoo manifest refuses malformed documents with a message naming the file, never a traceback."""

from __future__ import annotations

import json

import pytest

from predictors.errors import PredictorError
from predictors.zoo import read_manifest


@pytest.mark.parametrize(
    ("models", "message"),
    [({"a": 1}, '"models" must be a list'), ([1], "a zoo entry must be a JSON object, got 1")],
)
def test_malformed_manifest_is_a_predictor_error(tmp_path, models, message):
    (tmp_path / "manifest.json").write_text(json.dumps({"format": "crowdmpc-zoo", "models": models}))
    with pytest.raises(PredictorError, match=message):
        read_manifest(tmp_path)
