"""docs/examples/own_experiment.py: an experiment no shipped one holds, built as an ``Experiment`` and swept
from Python (``run_sweep``, ``write_report``), resumable as a sweep."""

import csv
import importlib.util
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "own_experiment.py"


def _example():
    spec = importlib.util.spec_from_file_location("own_experiment", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_own_experiment_example_sweeps_and_extends_its_table(tmp_path, capsys):
    example, out = _example(), tmp_path / "mine"
    example.main(str(out), 2, workers=1, backend="inline")
    first = capsys.readouterr().out
    assert first.startswith("8 episodes run, 0 already there, 0 errors\n")
    assert "| Metrics \\ Methods | full | 3 m | 3 m + 0.1 m | ORCA |" in first
    with open(out / "cells.csv", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [(r["method"], r["sensing"], r["margins"]) for r in rows] == [
        ("full", "every human", "none"),
        ("3 m", "3 m", "none"),
        ("3 m + 0.1 m", "3 m", "fixed0.1_0.1_0.1_0.1"),
        ("ORCA", "every human", "none"),
    ]
    assert {r["episodes"] for r in rows} == {"2"}
    example.main(str(out), 3, workers=1, backend="inline")  # the table extended, not rerun
    assert capsys.readouterr().out.startswith("4 episodes run, 8 already there, 0 errors\n")
