"""Own data through the commands: `data stats` of one file (repeated rows counted once, frame rates shown),
`data prepare --raw FILE`, a resume whose data changed, a held-out split that is the training data, and a
held-out coverage far below its target."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipelines.cli import main
from pipelines.commands.train_data import data_hashes, note_shared_data
from pipelines.experiments.calibration_report import coverage_notes
from tests.cli_calls import run_cli as run
from tests.predictors.samples import write_lines, write_tiny_ewap, write_walk_file


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))


def test_stats_of_one_file_counts_repeated_rows_once_and_shows_its_rate(tmp_path, capsys):
    walk = write_walk_file(tmp_path / "walk.ndjson")
    lines = walk.read_text().splitlines()
    walk.write_text("\n".join([*lines, *lines[2:7]]) + "\n")  # five track rows again, identical
    code, out, err = run(capsys, "data", "stats", str(walk))
    assert code == 0
    header, _, row = out.splitlines()[:3]
    assert header.split()[-1] == "fps" and row.split()[:3] == ["walk.ndjson", "2", "45"]
    assert row.split()[-1] == "2.5"
    shown = "5 track rows repeat an earlier one (same pedestrian and frame); counted once"
    assert err.splitlines() == [
        f"note: {walk}: {shown}",
        f"note: 2 scenes in {walk} are untagged (tag 0 or none: uncategorised, as `data prepare --no-tags` "
        "and TrajNet++'s test files write them): left out of the types column",
    ]


def test_untagged_scenes_are_said_with_their_cause(tmp_path, capsys):
    """A TrajNet++ test file's scenes are tagged 0 because its ground truth is withheld: the note blamed
    `data prepare --no-tags`, which wrote no such file; a prepared --no-tags folder's are its doing."""
    withheld = write_walk_file(tmp_path / "release" / "test" / "real_data" / "biwi_eth.ndjson")
    code, _, err = run(capsys, "data", "stats", str(tmp_path / "release"))
    assert code == 0 and err.splitlines() == [
        f"note: 2 scenes in {withheld} are untagged (a TrajNet++ test file tags every scene 0: its ground "
        "truth is withheld, and the tags with it; test_private/ holds both): left out of the types column"
    ]
    raw = write_tiny_ewap(tmp_path / "raw")
    assert (
        run(capsys, "data", "prepare", "--raw", str(raw), "--out", str(tmp_path / "p"), "--no-tags")[0] == 0
    )
    code, _, err = run(capsys, "data", "stats", str(tmp_path / "p"))
    assert code == 0 and err.splitlines()[-1].endswith(
        " in 6 files are untagged (`data prepare --no-tags` wrote them so): left out of the types column"
    )
    assert "withheld" not in err  # its test/ files hold the ground truth


def test_stats_shows_scenes_without_a_rate(tmp_path, capsys):
    records = [json.loads(line) for line in write_walk_file(tmp_path / "w.ndjson").read_text().splitlines()]
    for record in records:
        record.get("scene", {}).pop("fps", None)
    write_lines(tmp_path / "w.ndjson", records)
    code, out, _ = run(capsys, "data", "stats", str(tmp_path))
    assert code == 0 and out.splitlines()[2].split()[-1] == "none"


def test_prepare_of_an_obsmat_file_asks_for_its_folder(tmp_path, capsys):
    raw = write_tiny_ewap(tmp_path)
    obsmat = raw / "seq_eth" / "obsmat.txt"
    code, _, err = run(capsys, "data", "prepare", "--raw", str(obsmat), "--out", str(tmp_path / "out"))
    assert code == 2
    assert err.strip().endswith(f"--raw {obsmat} is a file; give the folder holding seq_eth/ and seq_hotel/")


def test_a_held_out_file_with_the_training_content_is_noted(tmp_path, capsys):
    train = write_walk_file(tmp_path / "train.ndjson")
    copy = tmp_path / "copy.ndjson"
    copy.write_bytes(train.read_bytes())
    other = write_lines(tmp_path / "other.ndjson", [json.loads(train.read_text().splitlines()[0])])
    files = {"train": [train], "val": [other], "test": [copy]}
    note_shared_data(files, data_hashes(files))
    err = capsys.readouterr().err
    assert err.startswith(f"note: --test {copy} holds the same data as --train {train} (sha256 ")
    assert err.count("\n") == 1 and "test metrics are not on held-out data" in err
    files = {"train": [train], "val": [other], "test": [other]}  # the same file: named once
    note_shared_data(files, data_hashes(files))
    assert capsys.readouterr().err.startswith(f"note: --test {other} holds the same data as --val (sha256 ")


def test_a_validation_file_with_the_training_content_is_noted(tmp_path, capsys):
    """`train --train a.ndjson --val a.ndjson` said nothing of validating on the training data, where
    data/README.md says a --val file with a training file's content is noted: its best epoch and the
    validation metrics the zoo records are the training data's."""
    train = write_walk_file(tmp_path / "train.ndjson")
    copy = tmp_path / "copy.ndjson"
    copy.write_bytes(train.read_bytes())
    for val, other in ((train, "--train"), (copy, f"--train {train}")):  # the same file, and a copy
        files = {"train": [train], "val": [val], "test": []}
        hashes = data_hashes(files)
        note_shared_data(files, hashes)
        sha = hashes[str(train.resolve())]
        assert capsys.readouterr().err == (
            f"note: --val {val} holds the same data as {other} (sha256 {sha[:12]}…): "
            "the best epoch is chosen, and its validation metrics measured, on training data\n"
        )


def test_a_resume_refuses_a_data_file_changed_since_the_run_started(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("CROWDMPC_DATA", raising=False)
    walk = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    common = ["train", "--model", "vanilla_lstm", "--no-progress", "--out", str(out)]
    data = ["--train", str(walk), "--val", str(walk)]
    assert main([*common, *data, "--epochs", "1", "--batch-size", "2"]) == 0
    before = json.loads((out / "train_settings.json").read_text())["data_sha256"][str(walk.resolve())]
    records = [json.loads(line) for line in walk.read_text().splitlines()]
    records[2]["track"]["x"] = 0.25  # the same scenes, one position moved
    write_lines(walk, records)
    assert main([*common, "--epochs", "2", "--resume"]) == 2
    error = capsys.readouterr().err.splitlines()[-1]
    assert f"--resume: data file {walk.resolve()} has changed since the run in {out} started" in error
    assert f"sha256 {before} then, " in error and "start a new run" in error


def test_held_out_coverage_far_below_its_target_is_noted():
    rng = np.random.default_rng(0)
    holdout = rng.uniform(0, 1, size=(200, 2))
    assert coverage_notes([0.1], holdout, [(0.89, 0.86)]) == ""  # within chance of 90 % over 200 samples
    note = coverage_notes([0.1], holdout, [(0.90, 0.33)])
    assert note.startswith("note: alpha 0.1: held-out coverage 33.0% at step 2 is below the target 90%")
    assert note.endswith("its margins may not hold on this data\n") and note.count("\n") == 1
    assert coverage_notes([0.1], None, None) == ""


def test_train_help_says_training_files_need_exact_scenes_and_val_and_test_files_are_cut():
    from pipelines.commands.train import EPILOG

    text = " ".join(EPILOG.split())
    assert "--val and --test files are read as `crowdmpc evaluate` reads them (the last 21 steps" in text
    assert "--train files' scenes must have exactly 21 steps" in text
