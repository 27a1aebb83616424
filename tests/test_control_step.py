"""benchmarks/control_step.py: the figures it prints are the figures it writes."""

import json

import pytest

from tests.benchmark_modules import load_benchmark

control_step = load_benchmark("control_step")


def test_the_cmpc_to_floor_ratio_is_that_of_the_medians_and_is_written(tmp_path, capsys):
    """The "cmpc / floor" ratio was printed, never written, and did not say which ratio it was."""
    out = tmp_path / "cs.json"
    assert control_step.main(["--humans", "0", "--episodes", "1", "--json", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    cmpc = rows["cmpc      0 humans"]
    assert cmpc["median_over_floor_median"] == pytest.approx(cmpc["median_ms"] / cmpc["floor"]["median_ms"])
    printed = f"{'  median cmpc / median floor':<30} {cmpc['median_over_floor_median']:10.2f}"
    assert printed in capsys.readouterr().out.splitlines()
