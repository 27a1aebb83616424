"""benchmarks/replay_coverage.py: the shipped margins' coverage of closed-loop scores, by hand, and its
command line."""

import json
import math
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from pipelines.loop.margins import parse_margins
from predictors.registry import checkpoint_sha256
from tests.benchmark_modules import BENCHMARKS, load_benchmark

replay_coverage = load_benchmark("replay_coverage")
ROOT = Path(__file__).resolve().parents[1]


def test_coverage_is_the_share_of_scores_within_each_steps_margin():
    margins = parse_margins("conformal:0.1").resolve("constant_velocity", 4, None)
    errors = np.array(
        [
            [margins[0] - 0.01, margins[1] + 0.01, math.nan, margins[3]],  # on the margin counts as within
            [margins[0] + 0.01, margins[1] - 0.01, margins[2] - 0.01, margins[3] + 0.01],
        ]
    )
    observer = SimpleNamespace(errors=errors, shortfall=np.zeros_like(errors), classes=np.array([0, 3]))
    shares = replay_coverage.coverage(observer, "conformal:0.1", "constant_velocity", 4)
    assert shares == [0.5, 0.5, 1.0, 0.5]  # step 3: one score, within


def test_class_margins_take_each_humans_own_class_and_shortfall_its_own_score():
    table = parse_margins("conformal-shortfall:0.05").resolve_classes("constant_velocity", 4, None)
    new, walking = np.asarray(table.quantiles[0][:4]), np.asarray(table.quantiles[3][:4])
    assert (new != walking).any()  # else the test could not tell the classes apart
    shortfall = np.stack([new, walking]) - 1e-9  # each just within its own class's margin
    observer = SimpleNamespace(errors=np.full((2, 4), 99.0), shortfall=shortfall, classes=np.array([0, 3]))
    assert replay_coverage.coverage(observer, "conformal-shortfall:0.05", "constant_velocity", 4) == [1.0] * 4
    swapped = SimpleNamespace(**{**observer.__dict__, "classes": np.array([3, 0])})
    expected = [float(np.mean([n <= w, w <= n])) for n, w in zip(new, walking, strict=True)]
    assert replay_coverage.coverage(swapped, "conformal-shortfall:0.05", "constant_velocity", 4) == expected
    assert checkpoint_sha256("constant_velocity") is None  # a weightless predictor: no sha256 to resolve


def test_the_script_reports_each_crowd_and_writes_its_json(tmp_path):
    out = tmp_path / "coverage.json"
    run = [sys.executable, str(BENCHMARKS / "replay_coverage.py"), "--predictor", "constant_velocity"]
    done = subprocess.run(
        [*run, "--crowds", "orca", "--episodes", "2", "--margins", "conformal:0.1", "--json", str(out)],
        capture_output=True, text=True, timeout=300, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert (
        lines[0] == "constant_velocity, planning with margins none: coverage at k = 1..4 (target 1 - alpha)"
    )
    assert lines[1].startswith("orca: 2 episodes, ") and lines[2].split()[0] == "conformal:0.1"
    report = json.loads(out.read_text())
    shares = report["crowds"]["orca"]["coverage"]["conformal:0.1"]
    assert len(shares) == 4 and all(0.0 <= s <= 1.0 for s in shares)
    typo = subprocess.run(
        [*run, "--margins", "conformal:1.5"], capture_output=True, text=True, timeout=120, cwd=ROOT
    )
    assert typo.returncode == 2 and len(typo.stderr.splitlines()) == 1 and "Traceback" not in typo.stderr
    assert report["sensor_range"] is None


def test_the_script_scores_behind_a_sensor(tmp_path):
    out = tmp_path / "coverage.json"
    run = [sys.executable, str(BENCHMARKS / "replay_coverage.py"), "--predictor", "constant_velocity"]
    done = subprocess.run(
        [*run, "--crowds", "orca", "--episodes", "2", "--margins", "conformal-motion:0.1", "--sensor-range",
         "2.5", "--json", str(out)],
        capture_output=True, text=True, timeout=300, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("constant_velocity, planning with margins none, behind a sensor of 2.5 m: ")
    report = json.loads(out.read_text())
    assert report["sensor_range"] == 2.5 and report["crowds"]["orca"]["scored_at_k1"] > 0
    for bad in ("0", "inf", "nan"):
        refused = subprocess.run(
            [*run, "--sensor-range", bad], capture_output=True, text=True, timeout=120, cwd=ROOT
        )
        assert refused.returncode == 2 and "--sensor-range must be" in refused.stderr


def test_a_crowd_that_never_came_near_has_no_coverage_and_is_printed_so(capsys):
    """1 person of eth who never came within --near of a robot left PredictionErrors' empty (0, 0) arrays,
    and broadcasting a margin to them ended the script in a ValueError traceback."""
    empty = SimpleNamespace(errors=np.zeros((0, 0)), shortfall=np.zeros((0, 0)), classes=np.zeros(0, int))
    for margins in ("conformal:0.1", "conformal-shortfall:0.05"):
        shares = replay_coverage.coverage(empty, margins, "constant_velocity", 4)
        assert len(shares) == 4 and all(math.isnan(share) for share in shares)
    eth = {
        "episodes": 1,
        "success": 1,
        "collision": 0,
        "scored_at_k1": 0,
        "coverage": {"conformal:0.1": shares},
    }
    report = {"predictor": "constant_velocity", "plan_with": "none", "crowds": {"eth": eth}}
    replay_coverage.print_report(report, 4)
    assert capsys.readouterr().out.splitlines()[-1].split() == ["conformal:0.1", "-", "-", "-", "-"]


def test_a_crowd_or_margins_named_twice_is_refused_before_any_episode(monkeypatch, capsys):
    """--crowds orca orca ran the crowd's episodes twice (the same seeds) and the report, keyed by crowd,
    printed and wrote one; --margins scored one margin twice and kept one."""

    def no_episodes(*args, **kwargs):
        raise AssertionError("an episode ran; the command line should have been refused")

    monkeypatch.setattr(replay_coverage, "scores", no_episodes)
    for argv, repeated in (
        (["--crowds", "orca", "hotel_test", "orca"], "--crowds names orca more than once"),
        (["--margins", "conformal:0.1", "conformal:0.1"], "--margins names conformal:0.1 more than once"),
    ):
        monkeypatch.setattr(sys, "argv", ["replay_coverage.py", *argv, "--episodes", "1"])
        with pytest.raises(SystemExit) as exit_:
            replay_coverage.main()
        assert exit_.value.code == 2
        out, err = capsys.readouterr()
        assert out == ""
        assert err.splitlines()[-1] == f"replay_coverage.py: error: {repeated}"
