"""The CLI's notes and warnings name the user's paths as its error line does: a path holding a line break
(`data stats $'a\\nb'`) ran a note over two lines, where the error line (pipelines.errors.one_line) stays on
one. Each is now written on one line, its control characters as Python escapes."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from pipelines.errors import DroppedLineWarning, warnings_as_notes
from tests.cli_calls import run_cli as run
from tests.predictors.samples import write_walk_file


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))


def test_a_note_naming_a_path_with_a_line_break_is_one_line(tmp_path, capsys):
    walk = write_walk_file(tmp_path / "a\nb" / "walk.ndjson")
    lines = walk.read_text().splitlines()
    walk.write_text("\n".join([*lines, *lines[2:7]]) + "\n")  # five track rows again: a note names the file
    code, _, err = run(capsys, "data", "stats", str(walk))
    escaped = str(walk).replace("\n", "\\n")
    assert code == 0
    assert err.splitlines()[0] == (
        f"note: {escaped}: 5 track rows repeat an earlier one (same pedestrian and frame); counted once"
    )
    assert len(err.splitlines()) == 2  # and the untagged scenes' note, naming it too


def test_a_resume_note_naming_an_out_with_a_line_break_is_one_line(capsys):
    from pipelines.experiments.sweep import _note_other_code

    capsys.readouterr()
    _note_other_code(Path("runs/a\nb"), [{}])  # a run from before the code was recorded
    err = capsys.readouterr().err
    assert err.startswith("note: runs/a\\nb holds episodes made by other code (code not recorded -> ")
    assert len(err.splitlines()) == 1


def test_a_warning_shown_as_a_note_is_one_line(capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings_as_notes()
        warnings.warn(DroppedLineWarning("runs/a\nb/episodes.jsonl ended in a cut line"), stacklevel=1)
    assert capsys.readouterr().err == "note: runs/a\\nb/episodes.jsonl ended in a cut line\n"


def test_reviews_unreadable_recording_naming_a_line_break_is_one_line(tmp_path, capsys):
    """`crowdmpc review FOLDER` wrote each unreadable recording's line with tqdm.write, past print_note: a
    recording named $'a\\nb.mcap' ran it over two lines ("unreadable: FOLDER/a", "b.mcap is not an MCAP
    file ...")."""
    (tmp_path / "a\nb.mcap").write_bytes(b"garbage")
    code, _, err = run(capsys, "review", str(tmp_path))
    assert code == 2
    assert err.splitlines()[0] == (
        f"crowdmpc review: unreadable: {tmp_path}/a\\nb.mcap is not an MCAP file (it does not start with "
        "MCAP's magic bytes)"
    )
    assert len(err.splitlines()) == 2  # and the error line: no readable recording
