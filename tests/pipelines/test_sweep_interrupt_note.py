"""What an interrupted sweep says and exits with: "rerun to resume" only while something is left to run."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from pipelines.commands import sweep_report
from pipelines.experiments.sweep import SweepOutcome


@pytest.mark.parametrize(
    ("done", "said"),
    [
        (4, "interrupted after every planned episode was recorded: the report follows"),
        (3, "interrupted: rerun the same command to resume"),
    ],
)
def test_a_sweep_interrupted_after_its_last_episode_says_nothing_is_left(done, said, monkeypatch, capsys):
    """A Ctrl-C that came after "4/4 episodes recorded" printed "rerun the same command to resume"."""
    outcome = SweepOutcome(planned=4, already_done=0, ran=done, backend="process", interrupted=True)
    monkeypatch.setattr("pipelines.experiments.sweep.run_sweep", lambda config, records=None: outcome)
    monkeypatch.setattr(sweep_report, "_recorded", lambda config: done)
    config = SimpleNamespace(experiment=SimpleNamespace(name="table2"), out="x")
    assert sweep_report.run_cells(config) == sweep_report.INTERRUPTED  # type: ignore[arg-type]
    err = capsys.readouterr().err
    assert f"table2: {done}/4 episodes recorded" in err and said in err
