"""``crowdmpc sweep --dry-run`` over a sweep folder, a resume's preview: it listed the planned cells but not
how many of their episodes the folder's log records, nor how many a resume would run."""

from __future__ import annotations

import pytest

from pipelines.cli import main
from pipelines.experiments.log import EPISODES_FILE, SWEEP_FILE
from tests.cli_calls import run_cli

ARGV = ["sweep", "--experiment", "baselines", "--backend", "inline", "--no-progress"]
OTHER = [
    "sweep",
    "--experiment",
    "controllers",
    "--controllers",
    "straight",
    "--backend",
    "inline",
    "--no-progress",
]


def test_a_dry_run_over_a_sweep_says_what_is_recorded_and_what_a_resume_runs(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main([*ARGV, "--humans", "3", "--episodes-per-cell", "1", "--out", str(out)]) == 0
    log = (out / EPISODES_FILE).read_bytes()
    # a torn last line is what a resume cuts off and runs again: not recorded, and the dry run leaves it
    (out / EPISODES_FILE).write_bytes(log + b'{"key": "torn')
    code, stdout, _ = run_cli(
        capsys, *ARGV, "--episodes-per-cell", "3", "--humans", "3,4", "--dry-run", "--out", str(out)
    )
    assert code == 0 and (out / EPISODES_FILE).read_bytes() == log + b'{"key": "torn'
    cells = [line.split() for line in stdout.splitlines() if " humans " in line]
    assert [(words[1], words[3], words[-1][-5:]) for words in cells] == [
        ("3", "1/3", "h3-r3"),
        ("3", "1/3", "h3-r3"),
        ("4", "0/3", "h4-r3"),
        ("4", "0/3", "h4-r3"),
    ]
    assert stdout.splitlines()[-1] == (
        f"2 of 12 planned episodes recorded in {out / EPISODES_FILE}; a resume runs 10"
    )


def test_a_dry_run_into_a_new_folder_lists_the_cells_alone(tmp_path, capsys):
    code, stdout, _ = run_cli(
        capsys,
        *ARGV,
        "--humans",
        "3",
        "--episodes-per-cell",
        "2",
        "--dry-run",
        "--out",
        str(tmp_path / "new"),
    )
    assert code == 0 and "recorded" not in stdout
    assert [len(line.split()) for line in stdout.splitlines()[1:]] == [4, 4]  # label, crowd size, key


def test_a_dry_run_into_a_folder_of_other_files_is_refused_as_the_run_is(tmp_path, capsys):
    """The dry run skipped the folder check its run makes, so it printed a plan for a folder of other files
    (a sweep's tables would overwrite them), which the run then refused."""
    out = tmp_path / "theirs"
    out.mkdir()
    (out / "foo").write_text("not a sweep's\n")
    argv = [*ARGV, "--humans", "3", "--episodes-per-cell", "1", "--out", str(out)]
    code, stdout, stderr = run_cli(capsys, *argv, "--dry-run")
    assert code == 2 and stdout == ""
    assert f"{out} holds files but no sweep" in stderr and len(stderr.strip().splitlines()) == 1
    assert run_cli(capsys, *argv)[2] == stderr  # the run's refusal, word for word
    assert [p.name for p in out.iterdir()] == ["foo"]


@pytest.mark.parametrize(
    ("damage", "argv"),
    [
        (lambda text: b"\xff" + text, ARGV),  # no UTF-8: the resume reads sweep.json, the dry run did not
        (lambda text: text, OTHER),  # a folder of the baselines
    ],
    ids=["unreadable", "another-experiment"],
)
def test_a_dry_run_refuses_the_sweep_file_the_resume_refuses(tmp_path, capsys, damage, argv):
    """The dry run read the folder's log and not its sweep.json, so it said "a resume runs N" of a folder
    whose sweep.json the resume then refused: one it could not read, or of another experiment."""
    out = tmp_path / "sweep"
    assert main([*ARGV, "--humans", "3", "--episodes-per-cell", "1", "--out", str(out)]) == 0
    damaged = damage((out / SWEEP_FILE).read_bytes())
    (out / SWEEP_FILE).write_bytes(damaged)
    argv = [*argv, "--humans", "3", "--episodes-per-cell", "2", "--out", str(out)]
    code, stdout, stderr = run_cli(capsys, *argv, "--dry-run")
    assert code == 2 and stdout == "" and len(stderr.strip().splitlines()) == 1
    assert run_cli(capsys, *argv)[2] == stderr  # the run's refusal, word for word
    assert (out / SWEEP_FILE).read_bytes() == damaged
