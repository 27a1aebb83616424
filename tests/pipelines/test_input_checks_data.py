"""Inputs of `crowdmpc evaluate`, `train` and `data` that hold nothing to work on, or seeds out of every
command's range: refused in one line (exit 2), before any work, where they passed with an empty result."""

from __future__ import annotations

import pytest

from pipelines.cli import main
from tests.cli_calls import one_line, parser_error, run_cli
from tests.predictors.samples import ewap_rows, write_lines, write_obsmat, write_tiny_ewap, write_walk_file


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))


def refused(capsys, *argv: str) -> tuple[str, str]:
    """The one error line of a command refused with exit 2, and what it printed on stdout."""
    code, out, err = run_cli(capsys, *argv)
    assert code == 2, (out, err)
    return one_line(err), out


@pytest.mark.parametrize("with_walk", [False, True], ids=["alone", "beside-a-file-with-scenes"])
def test_evaluate_refuses_a_test_file_without_scenes(with_walk, tmp_path, capsys):
    empty = write_lines(tmp_path / "empty.ndjson", [])
    files = [str(write_walk_file(tmp_path / "walk.ndjson"))] if with_walk else []
    line, out = refused(capsys, "evaluate", "--predictor", "constant_velocity", "--test", *files, str(empty))
    assert line == (
        f"crowdmpc evaluate: error: --test {empty}: holds no scenes; the evaluation needs at least one"
    )
    assert "ADE" not in out  # no table of a "0 scenes -" row


def test_evaluate_refuses_a_prepared_split_without_scenes_naming_it(tmp_path, capsys):
    """Raw ETH data too short for a test split: the preparation writes it empty, and its row read "0 -"."""
    raw = write_tiny_ewap(tmp_path / "data")
    write_obsmat(raw / "seq_eth" / "obsmat.txt", ewap_rows(100, 6))
    argv = [
        "evaluate",
        "--predictor",
        "constant_velocity",
        "--data-dir",
        str(tmp_path / "data"),
        "--no-progress",
    ]
    # first the hotel's, which has scenes (and prepares the data, whose log is on stderr)
    code, out, _ = run_cli(capsys, *argv, "--dataset", "biwi_hotel")
    assert code == 0 and "test/biwi_hotel.ndjson" in out
    line, out = refused(capsys, *argv)
    assert "evaluate: error: the test split test/biwi_eth.ndjson of " in line
    assert line.endswith(
        "holds no scenes; evaluate another --dataset or --split, or prepare data with more frames"
    )
    assert "ADE" not in out


def test_evaluate_names_a_data_directory_that_does_not_exist(tmp_path, capsys):
    missing = tmp_path / "nonexist"
    line, _ = refused(capsys, "evaluate", "--predictor", "constant_velocity", "--data-dir", str(missing))
    assert line == f"crowdmpc evaluate: error: data directory {missing} does not exist"


def test_train_refuses_an_empty_test_file_before_training(tmp_path, capsys):
    empty = write_lines(tmp_path / "empty.ndjson", [])
    walk = str(write_walk_file(tmp_path / "walk.ndjson"))
    out = tmp_path / "run"
    argv = ["train", "--model", "vanilla_lstm", "--train", walk, "--val", walk, "--test", str(empty)]
    line, _ = refused(
        capsys, *argv, "--epochs", "1", "--limit-batches", "1", "--no-progress", "--out", str(out)
    )
    assert line == f"crowdmpc train: error: --test {empty}: holds no scenes; test needs at least one"
    assert not out.exists()  # refused before the run folder is made


SEEDS = [
    ("-1", "expected an integer >= 0, got -1"),
    (
        "99999999999999999999999",
        "must be at most 2**63 - 1 (TOML's largest integer), got 99999999999999999999999",
    ),
    (str(2**63), f"must be at most 2**63 - 1 (TOML's largest integer), got {2**63}"),
]


@pytest.mark.parametrize(("seed", "message"), SEEDS, ids=["negative", "huge", "2**63"])
@pytest.mark.parametrize("command", ["prepare", "synth", "evaluate"])
def test_a_seed_out_of_range_is_refused_as_by_every_command(command, seed, message, tmp_path, capsys):
    raw = write_tiny_ewap(tmp_path / "data")
    argv = {
        "prepare": ["data", "prepare", "--raw", str(raw), "--out", str(tmp_path / "out")],
        "synth": ["data", "synth", "--out", str(tmp_path / "s.ndjson"), "--episodes", "1", "--humans", "3"],
        "evaluate": [
            "evaluate",
            "--predictor",
            "constant_velocity",
            "--test",
            str(write_walk_file(tmp_path / "w")),
        ],
    }[command]
    line = parser_error(capsys, *argv, "--seed", seed)
    assert f"error: argument --seed: {message}; see " in line
    assert not (tmp_path / "out").exists() and not (tmp_path / "s.ndjson").exists()


@pytest.mark.parametrize(
    ("command", "episodes", "said"),
    [
        (["data", "synth", "--humans", "3"], "3", "3 episodes"),
        (["calibrate", "--holdout"], "2", "4 episodes with --holdout"),
    ],
)
def test_a_run_whose_last_episode_passes_the_largest_seed_is_refused(
    command, episodes, said, tmp_path, capsys
):
    """synth and calibrate run episode i at seed + i: the last passed 2**63 - 1 and was recorded under a seed
    no command takes (calibrate's --holdout runs as many more on the seeds after)."""
    out = tmp_path / "s.ndjson"
    options = ["--out", str(out)] if command[0] == "data" else ["--predictor", "constant_velocity"]
    options += ["--source", "closed-loop", "--alpha", "0.1", "--dry-run"] if command[0] == "calibrate" else []
    line, _ = refused(capsys, *command, *options, "--episodes", episodes, "--seed", str(2**63 - 2))
    n = int(said.split()[0])
    assert f"--seed must be at most {2**63 - n} with {said} (its last episode's seed, seed + {n - 1}" in line
    assert not out.exists()


def test_the_largest_seed_is_taken(tmp_path, capsys):
    walk = str(write_walk_file(tmp_path / "walk.ndjson"))
    assert (
        main(["evaluate", "--predictor", "constant_velocity", "--test", walk, "--seed", str(2**63 - 1)]) == 0
    )
    raw = write_tiny_ewap(tmp_path / "data")
    argv = ["data", "prepare", "--raw", str(raw), "--out", str(tmp_path / "out"), "--no-check"]
    assert main([*argv, "--seed", str(2**63 - 1)]) == 0
