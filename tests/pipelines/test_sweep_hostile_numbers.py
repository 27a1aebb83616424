"""Sweep folders holding JSON that json reads unlike its other files: an integer literal longer than
Python's 4300 digits (json's parser raises a plain ValueError for it, no JSONDecodeError, which ended a
report, a resume, --reuse and compare in a traceback), a key given twice (json keeps the last)."""

import shutil
from pathlib import Path

import pytest

from pipelines.cli import main
from pipelines.experiments.log import EPISODES_FILE, ERRORS_FILE, SWEEP_FILE, error_keys
from pipelines.experiments.sweep import run_sweep
from tests.pipelines.test_sweep_hostile import ARGV, DEEP, _config

LONG = b'{"key": "x", "seed": 1' + b"0" * 5000 + b"}\n"  # int("1000...") past sys.get_int_max_str_digits()


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("good")
    run_sweep(_config(out))
    return out


def _with_long_line(good: Path, out: Path) -> Path:
    shutil.copytree(good, out)
    first, second = (good / EPISODES_FILE).read_bytes().splitlines(keepends=True)
    (out / EPISODES_FILE).write_bytes(first + LONG + second)
    return out


@pytest.mark.parametrize(
    "argv",
    [
        [*ARGV, "--report-only", "--out", "{out}"],
        [*ARGV, "--out", "{out}"],
        [*ARGV, "--dry-run", "--out", "{out}"],
        [*ARGV, "--out", "{new}", "--reuse", "{out}"],
        ["compare", "a={out}", "b={good}"],
    ],
    ids=["report", "resume", "dry-run", "reuse", "compare"],
)
def test_a_record_with_an_integer_past_4300_digits_is_named_by_file_and_line(good, tmp_path, capsys, argv):
    out = _with_long_line(good, tmp_path / "sweep")
    before = (out / EPISODES_FILE).read_bytes()
    code = main([a.format(out=out, good=good, new=tmp_path / "new") for a in argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert f"{out / EPISODES_FILE}:2: not a JSON record (" in err[0] and "4300 digits" in err[0]
    assert (out / EPISODES_FILE).read_bytes() == before


def test_such_a_last_line_is_cut_off_and_kept_as_a_torn_one_is(good, tmp_path, capsys):
    out = tmp_path / "sweep"
    shutil.copytree(good, out)
    log = (out / EPISODES_FILE).read_bytes()
    (out / EPISODES_FILE).write_bytes(log + LONG)
    assert main([*ARGV, "--out", str(out)]) == 0
    assert (out / EPISODES_FILE).read_bytes() == log
    assert (out / (EPISODES_FILE + ".cut")).read_bytes() == LONG


@pytest.mark.parametrize("line", [LONG, DEEP], ids=["long_int", "deeply_nested"])
def test_such_an_error_entry_is_passed_over(good, tmp_path, line):
    """errors.jsonl only orders a rerun's episodes: a line that is no entry is passed over, this one too."""
    out = tmp_path / "sweep"
    shutil.copytree(good, out)
    (out / ERRORS_FILE).write_bytes(b'{"key": "y"}\n' + line)
    assert error_keys(out) == {"y"}
    assert main([*ARGV, "--out", str(out)]) == 0


@pytest.mark.parametrize(
    "argv",
    [[*ARGV, "--out", "{out}"], [*ARGV, "--report-only", "--out", "{out}"]],
    ids=["resume", "report"],
)
def test_a_sweep_file_naming_a_key_twice_is_refused_and_left_as_it_was(good, tmp_path, capsys, argv):
    """json keeps the last of a key given twice: a resume took `"runs": []` typed after the runs, ran, and
    wrote sweep.json back with its own run alone, the earlier runs' records lost."""
    out = tmp_path / "sweep"
    shutil.copytree(good, out)
    text = (out / SWEEP_FILE).read_text().rstrip()
    damaged = (text[:-1] + ', "runs": []}').encode()
    (out / SWEEP_FILE).write_bytes(damaged)
    assert main([a.format(out=out) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"crowdmpc sweep: error: {out / SWEEP_FILE}: the key 'runs' appears twice in one object; give each "
        "key once (json would keep the last); restore it, or move it away (the episodes it listed are then "
        "kept as runs of unknown code; a new --out starts afresh)"
    ]
    assert (out / SWEEP_FILE).read_bytes() == damaged
