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
