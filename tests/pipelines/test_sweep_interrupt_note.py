"""What an interrupted sweep says and exits with: "rerun to resume" only while something is left to run."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from pipelines.commands import sweep_run
from pipelines.experiments.sweep import SweepOutcome


@pytest.mark.parametrize(
    ("done", "cut", "said"),
    [
        (4, 0, "interrupted after every planned episode was recorded: the report follows"),
        (3, 0, "interrupted: rerun the same command to resume\n"),
        (
            2,
            2,
            "interrupted: rerun the same command to resume; 2 episodes in flight on the workers were cut "
            "unrecorded (a resume runs them)",
        ),
    ],
)
def test_a_sweep_interrupted_after_its_last_episode_says_nothing_is_left(
    done, cut, said, tmp_path, monkeypatch, capsys
):
    """A Ctrl-C that came after "4/4 episodes recorded" printed "rerun the same command to resume"; one
    whose wait for the workers' episodes (pipelines.experiments.sweep_stop) cut some says how many."""
    outcome = SweepOutcome(planned=4, already_done=0, ran=done, backend="process", interrupted=True, cut=cut)
    monkeypatch.setattr(
        "pipelines.experiments.sweep.run_sweep",
        lambda config, records=None, weights=None, calibrations=None: outcome,
    )
    monkeypatch.setattr(sweep_run, "_recorded", lambda config: done)
    config = SimpleNamespace(experiment=SimpleNamespace(name="table2"), out=tmp_path, tasks=lambda: [])
    assert sweep_run.run_cells(config) == (sweep_run.INTERRUPTED, None)  # type: ignore[arg-type]
    err = capsys.readouterr().err
    assert f"table2: {done}/4 episodes recorded" in err and said in err


def test_a_sweep_complete_after_its_retries_says_its_errors_are_recorded_since(tmp_path, monkeypatch, capsys):
    """After a worker died and the rerun retried its 4 episodes, the folder was complete but errors.jsonl
    still listed them with nothing to say they had been retried, as if they still failed."""
    (tmp_path / "errors.jsonl").write_text(
        '{"key": "a", "error": "worker died"}\n{"key": "z", "error": "x"}\n'
    )
    outcome = SweepOutcome(planned=2, already_done=1, ran=1, backend="process")
    monkeypatch.setattr(
        "pipelines.experiments.sweep.run_sweep",
        lambda config, records=None, weights=None, calibrations=None: outcome,
    )
    tasks = [SimpleNamespace(key="a"), SimpleNamespace(key="b")]  # "z": another plan's
    config = SimpleNamespace(experiment=SimpleNamespace(name="table2"), out=tmp_path, tasks=lambda: tasks)
    assert sweep_run.run_cells(config) == (0, None)  # type: ignore[arg-type]
    err = capsys.readouterr().err
    assert "lists 1 episode(s) of this plan that raised in an earlier run; each is recorded since" in err
    outcome.ran = 0  # incomplete: the retries are still to come, nothing to say
    assert sweep_run.run_cells(config) == (0, None)  # type: ignore[arg-type]
    assert "recorded since" not in capsys.readouterr().err
