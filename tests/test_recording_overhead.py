"""benchmarks/recording_overhead.py: what its rows say was run."""

import pytest

from tests.benchmark_modules import load_benchmark

recording_overhead = load_benchmark("recording_overhead")


@pytest.mark.parametrize(
    "controller, predictor", [("straight", None), ("orca", None), ("cmpc", "constant_velocity")]
)
def test_a_row_names_the_predictor_its_episodes_ran_and_a_baseline_none(controller, predictor):
    """--controller straight printed "straight (constant_velocity)" and wrote that predictor to its JSON,
    for episodes that record none: a baseline predicts nothing."""
    row = recording_overhead.measure(controller, "constant_velocity", 1, 1)
    assert row["predictor"] == predictor
    assert row["steps"] > 0 and row["recording_s"] > 0
