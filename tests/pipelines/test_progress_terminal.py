"""Progress is drawn on a terminal only: simulate, sweep and evaluate drew their bars into a log that was no
terminal (a batch job's, ``2> run.log``) unless told ``--no-progress``, as review, compare and data synth
already did not; ``train`` writes one line an epoch there instead of Lightning's bars."""

from __future__ import annotations

import re
import sys

import pytest

from pipelines.cli import main
from tests.predictors.samples import write_crowds


def _argv(command: str, tmp_path) -> list[str]:
    if command == "simulate":
        return ["simulate", "--controller", "straight", "--humans", "2", "--episodes", "2"]
    if command == "sweep":
        return ["sweep", "--experiment", "controllers", "--controllers", "straight", "--humans", "1",
                "--episodes-per-cell", "2", "--backend", "inline", "--out", str(tmp_path / "s")]  # fmt: skip
    data = str(write_crowds(tmp_path / "crowds.ndjson"))
    return ["evaluate", "--predictor", "constant_velocity", "--test", data]


@pytest.mark.parametrize("command", ["simulate", "sweep", "evaluate"])
@pytest.mark.parametrize("terminal", [False, True])
def test_a_bar_is_drawn_on_a_terminal_only(command, terminal, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys.stderr, "isatty", lambda: terminal)  # tqdm asks its file, stderr
    assert main(_argv(command, tmp_path)) == 0
    err = capsys.readouterr().err
    rate = re.compile(r"[\d?](scene|ep)/s")  # tqdm's "12.3ep/s" ("?ep/s" before the first)
    assert (rate.search(err) is not None) is terminal and ("\r" in err) is terminal, err


def test_no_progress_draws_no_bar_on_a_terminal(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main([*_argv("simulate", tmp_path), "--no-progress"]) == 0
    assert "\r" not in capsys.readouterr().err


def _train(tmp_path, *extra: str) -> str:
    data = str(write_crowds(tmp_path / "crowds.ndjson"))
    files = ["--train", data, "--val", data, "--test", data]
    argv = ["train", "--model", "vanilla_lstm", *files, "--batch-size", "2", "--epochs", "2"]
    return [*argv, "--seed", "3", "--out", str(tmp_path / "run"), *extra]


def test_train_writes_a_line_an_epoch_where_stderr_is_no_terminal(tmp_path, capsys):
    import json

    assert main(_train(tmp_path)) == 0
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("epoch ")]
    assert [line.split(":")[0] for line in lines] == ["epoch 1/2", "epoch 2/2"] and "\r" not in err, err
    # the figures of the run's own log, as Lightning's CSV logger wrote them
    rows = [line.split(",") for line in (tmp_path / "run" / "csv" / "version_0" / "metrics.csv").open()]
    column = rows[0].index("val_ade")
    ades = [float(row[column]) for row in rows[1:] if row[column]]
    assert [f"val ADE {ade:.4g} m" in line for ade, line in zip(ades, lines, strict=True)] == [True, True]
    assert json.loads((tmp_path / "run" / "train_settings.json").read_text())  # a run like any other


def test_train_with_no_progress_writes_no_epoch_line(tmp_path, capsys):
    assert main(_train(tmp_path, "--no-progress")) == 0
    assert not [line for line in capsys.readouterr().err.splitlines() if line.startswith("epoch ")]


@pytest.mark.parametrize("after", [["sweep", "--report-only"], ["sweep"], ["config", "show", "--from-sweep"]])
@pytest.mark.parametrize("terminal", [False, True])
def test_reading_a_sweeps_log_draws_a_bar_on_a_terminal_only(after, terminal, tmp_path, capsys, monkeypatch):
    """A resume, a report and ``config show --from-sweep`` read the whole log first (~10,000 records a
    second), a million records in silence for minutes before."""
    argv = _argv("sweep", tmp_path)
    assert main([*argv, "--no-progress"]) == 0
    capsys.readouterr()
    monkeypatch.setattr(sys.stderr, "isatty", lambda: terminal)
    out = str(tmp_path / "s")
    assert main([*argv, *after[1:]] if after[0] == "sweep" else [*after, out]) == 0
    assert ("reading episodes.jsonl" in capsys.readouterr().err) is terminal


def test_no_progress_draws_no_bar_of_the_log_on_a_terminal(tmp_path, capsys, monkeypatch):
    argv = _argv("sweep", tmp_path)
    assert main([*argv, "--no-progress"]) == 0
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main([*argv, "--report-only", "--no-progress"]) == 0
    assert "reading episodes.jsonl" not in capsys.readouterr().err


@pytest.mark.parametrize("terminal", [False, True])
def test_writing_a_reports_episodes_csv_draws_a_bar_on_a_terminal_only(
    terminal, tmp_path, capsys, monkeypatch
):
    """Each row is read again from the log: 40 s at a million episodes, after the log's own bar."""
    argv = _argv("sweep", tmp_path)
    assert main([*argv, "--no-progress"]) == 0
    capsys.readouterr()
    monkeypatch.setattr(sys.stderr, "isatty", lambda: terminal)
    assert main([*argv, "--report-only"]) == 0
    err = capsys.readouterr().err
    assert ("writing episodes.csv" in err) is terminal
    assert (re.search(r"writing episodes.csv: +0%\|.*\| 0/2 \[", err) is not None) is terminal  # 2 rows


@pytest.mark.parametrize("dry_run", [[], ["--dry-run"]])
@pytest.mark.parametrize("terminal", [False, True])
def test_reuse_draws_a_bar_of_the_source_log_on_a_terminal_only(
    dry_run, terminal, tmp_path, capsys, monkeypatch
):
    """--reuse reads its source's log twice before the sweep starts: 10 s a read at 100,000 records."""
    argv = _argv("sweep", tmp_path)
    assert main([*argv, "--no-progress"]) == 0
    capsys.readouterr()
    monkeypatch.setattr(sys.stderr, "isatty", lambda: terminal)
    source = tmp_path / "s"
    assert main([*argv[:-1], str(tmp_path / "t"), "--reuse", str(source), *dry_run]) == 0
    assert (f"reading {source / 'episodes.jsonl'}" in capsys.readouterr().err) is terminal
