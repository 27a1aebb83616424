"""Reorganising the pipelines must not change what an episode does: the batch of ``behaviour.py`` (CMPC, DMPC,
the coupled NLP, the ORCA oracle, margins; one of them recorded to MCAP) against the stored outcome."""

import json
import math

import pytest

from tests.pipelines.behaviour import CASES, STORED, run_batch


def _is_nan(x) -> bool:
    return isinstance(x, float) and math.isnan(x)


def _close(a, b, path):
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{path}: {a!r} != {b!r}"
        for k in a:
            _close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), f"{path}: {a!r} != {b!r}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _close(x, y, f"{path}[{i}]")
    elif _is_nan(a) or _is_nan(b):
        # behaviour.py writes the stored file with json.dumps, which writes a float NaN as the literal NaN
        # (json.loads reads it back as NaN); the metrics' as_dict has already made a NaN metric None, stored
        # as null. So a NaN matches only a NaN: never a number, never null.
        assert _is_nan(a) and _is_nan(b), f"{path}: {a!r} != {b!r}"
    elif isinstance(a, float) and isinstance(b, float):
        # solvers' floating point can differ in the last bits between CPUs; behaviour cannot
        assert a == pytest.approx(b, rel=1e-6, abs=1e-9), f"{path}: {a!r} != {b!r}"
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


@pytest.mark.parametrize(
    ("a", "b", "same"),
    [
        (math.nan, math.nan, True),  # as json.loads reads a stored NaN back
        (None, None, True),  # a NaN metric: as_dict made it None, stored as null
        (1.0, 1.0 + 1e-12, True),
        (math.nan, None, False),
        (math.nan, 3, False),
        (math.nan, 0.0, False),
        (0.0, math.nan, False),
        (None, 0.0, False),
        (math.inf, math.nan, False),
        (2, 3, False),
        ({"x": math.nan}, {"x": 1.5}, False),
        ([1.0, math.nan], [1.0, None], False),
    ],
)
def test_close_lets_nan_match_only_nan(a, b, same):
    if same:
        _close(a, b, "v")
    else:
        with pytest.raises(AssertionError):
            _close(a, b, "v")


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    return run_batch(tmp_path_factory.mktemp("behaviour"))


@pytest.mark.parametrize("case", [*CASES, "mcap"])
def test_same_outcome_as_stored(batch, case):
    stored = json.loads(STORED.read_text())
    _close(batch[case], stored[case], case)
