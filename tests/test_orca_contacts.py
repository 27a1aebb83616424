"""benchmarks/orca_contacts.py: its summary names the time limit it ran; one agent (no pair) is refused, and
one robot has no robot-robot line."""

import sys

import pytest

from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from tests.benchmark_modules import load_benchmark

orca_contacts = load_benchmark("orca_contacts")


def test_the_summary_names_the_time_limit_the_episodes_ran(monkeypatch, capsys):
    """It printed "the 30 s time limit" (upstream CrowdNav's) while CrowdEnv() runs the paper profile's
    40 s: the figure is now the env's own."""
    argv = ["orca_contacts.py", "--humans", "2", "--robots", "1", "--episodes", "1"]
    monkeypatch.setattr(sys, "argv", argv)
    orca_contacts.main()
    out = capsys.readouterr().out
    assert f"episodes that hit the {EnvConfig().time_limit:g} s time limit: " in out
    # one robot: no robot-robot pair, said so (it printed "smallest distance inf m")
    assert "robot-robot  no pair of this kind" in out and "inf" not in out
    monkeypatch.setattr(orca_contacts, "CrowdEnv", lambda: CrowdEnv(EnvConfig(time_limit=25.0)))
    orca_contacts.main()
    assert "episodes that hit the 25 s time limit: " in capsys.readouterr().out


def test_a_single_agent_is_refused_when_parsed(monkeypatch, capsys):
    """One robot and no human have no pair: the episodes ran, then ``d.min()`` of no distance ended the
    script with numpy's traceback ("zero-size array to reduction operation minimum")."""
    argv = ["orca_contacts.py", "--humans", "0", "--robots", "1", "--episodes", "1"]
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as stop:
        orca_contacts.main()
    assert stop.value.code == 2
    assert "at least two agents make a pair" in capsys.readouterr().err
