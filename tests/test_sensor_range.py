"""benchmarks/sensor_range.py: its rows, paired episodes, and the radius it refuses."""

import argparse
import json
import sys

import pytest

from tests.benchmark_modules import load_benchmark

sensor_range = load_benchmark("sensor_range")


def test_a_row_for_full_observation_and_two_per_radius(tmp_path, monkeypatch, capsys):
    out = tmp_path / "rows.json"
    argv = ["--predictor", "social_lstm_eth", "--radii", "30", "--episodes", "2", "--humans", "3"]
    monkeypatch.setattr(sys, "argv", ["sensor_range.py", *argv, "--json", str(out)])
    sensor_range.main()
    rows = json.loads(out.read_text())["rows"]
    assert [row["row"] for row in rows] == [
        "full observation",
        "R = 30 m, tracks given",
        "R = 30 m, tracks not given",
    ]
    # 30 m sees everyone from the first step, tracked through the whole history: the full observation
    for key in ("success_pct", "collision_pct", "min_distance_median_m", "travel_mean_s"):
        assert len({row[key] for row in rows}) == 1, key
    assert "tracks not given" in capsys.readouterr().out


def test_no_human_prints_no_distance(monkeypatch, capsys):
    """Without a human no robot-human distance is measured: the table printed "inf" where the JSON has null
    and the other benchmarks print "-"."""
    argv = ["--predictor", "constant_velocity", "--radii", "4", "--humans", "0", "--episodes", "1"]
    monkeypatch.setattr(sys, "argv", ["sensor_range.py", *argv])
    sensor_range.main()
    out = capsys.readouterr().out
    rows = out.splitlines()[2:]
    assert len(rows) == 3 and "inf" not in out
    assert [line.split()[-2] for line in rows] == ["-"] * 3  # the min dist column, before travel s


@pytest.mark.parametrize("text", ["0", "-2", "inf", "nan", "x"])
def test_a_radius_that_is_no_finite_distance_is_refused(text):
    with pytest.raises(
        argparse.ArgumentTypeError, match="a sensor radius must be a finite number of metres > 0"
    ):
        sensor_range.radius(text)
