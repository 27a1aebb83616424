"""benchmarks/orca_contacts.py's summary names the time limit its simulator ran."""

import sys

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
    assert f"episodes that hit the {EnvConfig().time_limit:g} s time limit: " in capsys.readouterr().out
    monkeypatch.setattr(orca_contacts, "CrowdEnv", lambda: CrowdEnv(EnvConfig(time_limit=25.0)))
    orca_contacts.main()
    assert "episodes that hit the 25 s time limit: " in capsys.readouterr().out
