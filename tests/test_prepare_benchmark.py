"""benchmarks/prepare.py: each size timed once, in the order given, and the figures as JSON."""

import json
import sys

from tests.benchmark_modules import load_benchmark

prepare = load_benchmark("prepare")


def test_each_size_is_prepared_once_in_the_order_given(tmp_path, monkeypatch, capsys):
    out = tmp_path / "prepare.json"
    argv = ["--controller", "dmpc", "--predictor", "constant_velocity", "--humans", "4", "2", "4"]
    monkeypatch.setattr(sys, "argv", ["prepare.py", *argv, "--json", str(out)])
    prepare.main()
    figures = json.loads(out.read_text())
    assert (figures["controller"], figures["robots"], list(figures)[-1]) == ("dmpc", 3, "no_jit")
    seconds = figures["no_jit"]["seconds"]
    assert list(seconds) == ["4", "2"] and all(s > 0 for s in seconds.values())
    assert figures["no_jit"]["total_s"] >= sum(seconds.values())
    printed = capsys.readouterr().out
    assert "no jit: " in printed and "for 2 sizes" in printed


def test_the_memory_the_sizes_hold_is_reported(tmp_path, monkeypatch, capsys):
    """What a long-lived loop varying the crowd pays per size met (docs/extending.md, section 7): the
    resident memory the controller's sizes added, printed and in the JSON. Read around prepare alone: the
    whole suite's process reuses memory it freed, so a real reading can be 0 there (it was, once)."""
    readings = iter([100.0, 130.5])  # VmRSS before and after prepare, MB
    monkeypatch.setattr(prepare, "resident_mb", lambda: next(readings))
    out = tmp_path / "prepare.json"
    argv = ["--controller", "cmpc", "--predictor", "constant_velocity", "--robots", "2", "--humans", "3"]
    monkeypatch.setattr(sys, "argv", ["prepare.py", *argv, "--json", str(out)])
    prepare.main()
    assert json.loads(out.read_text())["no_jit"]["rss_mb"] == 30.5
    assert "for 1 size, +30 MB resident (load" in capsys.readouterr().out


def test_resident_memory_is_read_from_proc_where_there_is_one():
    held = prepare.resident_mb()
    assert held is None or held > 1.0  # this interpreter, torch and numpy loaded: far more than a megabyte
