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
