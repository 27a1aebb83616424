"""The benchmarks' printed headers and row labels count with predictors.text_table.counted: a run of one
human, robot or episode printed "1 humans", "1 ORCA robots", "1 episodes". Only the printed text: the JSON
keys docs/outputs.md documents stay as they are."""

import json

from tests.benchmark_modules import load_benchmark


def test_control_step_prints_one_human_and_keeps_the_documented_keys(tmp_path, capsys):
    control_step = load_benchmark("control_step")
    out = tmp_path / "cs.json"
    assert control_step.main(["--humans", "1", "--episodes", "1", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "1 humans" not in printed and "1 episodes" not in printed
    assert "1 episode per row" in printed
    labels = [line[:30].rstrip() for line in printed.splitlines()[3:] if not line.startswith("  ")]
    assert labels == ["cmpc      1 human", "floor     1 human", "dmpc      1 human"]
    keys = sorted(json.loads(out.read_text(encoding="utf-8"))["rows"])
    assert keys == ["cmpc      1 humans", "dmpc      1 humans", "floor     1 humans"]  # docs/outputs.md


def test_orca_step_counts_one_robot_and_one_episode(capsys):
    orca_step = load_benchmark("orca_step")
    orca_step.main(["--humans", "1", "--robots", "1", "--episodes", "1"])  # returns None
    header = capsys.readouterr().out.splitlines()[0]
    assert header == "CrowdEnv.step, circle crossing, 1 ORCA robot, 1 episode a size"


def test_orca_contacts_counts_one_episode_human_and_robot(monkeypatch, capsys):
    import sys

    orca_contacts = load_benchmark("orca_contacts")
    argv = ["orca_contacts.py", "--humans", "1", "--robots", "1", "--episodes", "1"]
    monkeypatch.setattr(sys, "argv", argv)
    orca_contacts.main()
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("1 episode, circle crossing, 1 human, 1 ORCA robot, seeds ")
    assert " / 1 episode;" in out[1]


def test_replay_coverage_counts_one_episode_success_and_score(capsys):
    replay_coverage = load_benchmark("replay_coverage")
    orca = {"episodes": 1, "success": 1, "collision": 1, "scored_at_k1": 1, "coverage": {}}
    report = {"predictor": "constant_velocity", "plan_with": "none", "crowds": {"orca": orca}}
    replay_coverage.print_report(report, 4)
    line = capsys.readouterr().out.splitlines()[1]
    assert line == "orca: 1 episode, 1 success, 1 with a collision; 1 score at k = 1 (a human at a step)"


def test_batching_counts_one_interleaved_epoch(tmp_path, capsys, monkeypatch):
    from tests.predictors.samples import write_crowds

    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    data = write_crowds(tmp_path / "crowds.ndjson")
    argv = ["--train", str(data), "--batch-size", "2", "--epochs", "1", "--model", "vanilla_lstm"]
    assert load_benchmark("batching").main(argv) == 0
    header = capsys.readouterr().out.splitlines()[0]
    assert header.endswith("; 1 interleaved epoch each"), header


def test_dmpc_scaling_counts_one_episode_cut_past_the_time_limit(capsys):
    from argparse import Namespace

    dmpc_scaling_table = load_benchmark("dmpc_scaling_table")
    row = {"median_ms": 1.0, "p95_ms": 1.0, "p99_ms": 1.0, "iterations_mean": 1.0, "at_j_max": 0.0}
    row |= {"solves_per_step": 3.0, "phase_ms_per_step": 1.0, "success": 1, "collision": 0, "timeout": 0}
    row |= {"episodes": 1}
    speedup = {"step_median": 1.0, "phase": 1.0}
    cell = {"rows": {"serial": row, "threads": row}, "speedup": speedup, "same": False, "cut": 1}
    report = {
        "cpus": 2,
        "load_before": [1.0],
        "load_after": [1.0],
        "wall_s": 1.0,
        "cells": {"r3 jacobi:regret": cell},
    }
    args = Namespace(humans=7, episodes=1)
    dmpc_scaling_table.print_report(report, args, "constant_velocity", ())
    note = capsys.readouterr().out.splitlines()[-1]
    assert note.endswith("(in 1 of 1 episode up to a step past the time limit)"), note


def test_prepare_counts_one_size(capsys):
    run = {"seconds": {"7": 0.5}, "total_s": 0.5, "load": [1.0, 1.0], "rss_mb": 9.0}
    load_benchmark("prepare").print_run("no jit", run)
    assert (
        capsys.readouterr().out.splitlines()[0]
        == "no jit: 0.50 s for 1 size, +9 MB resident (load 1.00 -> 1.00)"
    )


def test_plot_scaling_counts_one_row(tmp_path, capsys):
    row = {"controller": "cmpc", "goals": "fixed", "robots": 3, "success_rate": 100.0, "collision_rate": 0.0}
    row |= {"median_ms": 2.0, "p99_ms": 9.0}
    path = tmp_path / "one.json"
    path.write_text(json.dumps({"args": {"humans": 7}, "rows": [row]}), encoding="utf-8")
    assert load_benchmark("plot_scaling").main([str(path), "--out", str(tmp_path / "one.png")]) == 0
    assert f"wrote {tmp_path / 'one.png'} (0 of 1 row drawn)" in capsys.readouterr().out


def test_sweep_kills_counts_one_record(tmp_path, capsys, monkeypatch):
    import subprocess
    import sys
    from pathlib import Path

    sweep_kills = load_benchmark("sweep_kills")

    def out_of(cmd: list[str]) -> Path:
        return Path(cmd[cmd.index("--out") + 1])

    class Killed:  # a sweep that recorded one episode before its kill
        pid = 0

        def __init__(self, cmd, **kwargs):
            out_of(cmd).mkdir(exist_ok=True)
            (out_of(cmd) / "episodes.jsonl").write_text(json.dumps({"key": "a"}) + "\n", encoding="utf-8")

        def wait(self):
            return -9

    def finished(cmd, **kwargs):
        (out_of(cmd) / "sweep.json").write_text(json.dumps({"runs": [{"planned": 1}]}), encoding="utf-8")
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(sweep_kills.subprocess, "Popen", Killed)
    monkeypatch.setattr(sweep_kills.subprocess, "run", finished)
    monkeypatch.setattr(sweep_kills.time, "sleep", lambda seconds: None)
    monkeypatch.setattr(sweep_kills.os, "killpg", lambda pid, sig: None)
    monkeypatch.setattr(sys, "argv", ["sweep_kills.py", "--kills", "1"])
    assert sweep_kills.main() == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("kill  1 after ") and first.endswith(" s: 1 record"), first


def test_compile_cache_counts_one_episode_and_one_entry(capsys, monkeypatch):
    """The three sweeps stood in for (a sweep of one episode each) and the cache's listing of one entry."""
    import sys
    from types import SimpleNamespace

    from mpc import cache_admin

    compile_cache = load_benchmark("compile_cache")
    sweep = {"wall_s": 1.0, "episodes": 1, "episode_cpu_s": 0.5, "load_before": [1.0], "load_after": [1.0]}
    sweep |= {"metrics": {"a": 1}}
    monkeypatch.setattr(compile_cache, "run_sweep", lambda *args: dict(sweep))
    listing = SimpleNamespace(entries=1, size_bytes=1024, compiler="gcc")
    monkeypatch.setattr(cache_admin, "info", lambda folder: listing)
    argv = ["compile_cache.py", "--predictors", "constant_velocity", "--episodes-per-cell", "1"]
    monkeypatch.setattr(sys, "argv", [*argv, "--payback-episodes", "0"])
    assert compile_cache.main() == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("cold (--jit  on):    1.0 s wall, 1 episode using "), out[0]
    assert out[3] == "cache: 1 entry, 1 KiB; gcc"
