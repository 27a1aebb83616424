"""Reorganising the pipelines must not change what an episode does: the batch of ``behaviour.py`` (CMPC, DMPC,
the coupled NLP, the ORCA oracle, margins; one of them recorded to MCAP) against the stored outcome."""

import json
import math

import pytest

from tests.pipelines.behaviour import CASES, STORED, run_batch


def _close(a, b, path):
    if isinstance(a, dict):
        assert set(a) == set(b), f"{path}: keys {sorted(a)} != {sorted(b)}"
        for k in a:
            _close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _close(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float) and not (math.isnan(a) and math.isnan(b)):
        # solvers' floating point can differ in the last bits between CPUs; behaviour cannot
        assert a == pytest.approx(b, rel=1e-6, abs=1e-9), path
    elif not (isinstance(a, float) and math.isnan(a)):
        assert a == b, path


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    return run_batch(tmp_path_factory.mktemp("behaviour"))


@pytest.mark.parametrize("case", [*CASES, "mcap"])
def test_same_outcome_as_stored(batch, case):
    stored = json.loads(STORED.read_text())
    _close(batch[case], stored[case], case)
