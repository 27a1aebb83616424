"""``crowdmpc train`` refusing what a user can hand it by mistake, in one line: a damaged last.ckpt or a
folder in its place on --resume, and an --out folder of other files."""

from __future__ import annotations

import random
import shutil
from pathlib import Path

import pytest

from pipelines.cli import main
from tests.predictors.samples import write_walk_file

UNREADABLE = "is not a readable Lightning checkpoint (damaged, or not written by `crowdmpc train`; "


@pytest.fixture(autouse=True)
def _private_dirs(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))
    monkeypatch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path_factory.mktemp("shipped")))


def _args(data: Path, out: Path, epochs: int = 1) -> list[str]:
    return [
        "train",
        "--model",
        "vanilla_lstm",
        "--train",
        str(data),
        "--val",
        str(data),
        "--epochs",
        str(epochs),
        "--limit-batches",
        "1",
        "--out",
        str(out),
        "--no-progress",
    ]


@pytest.fixture(scope="module")
def one_run(tmp_path_factory) -> tuple[Path, Path]:
    """The walk data and a run of one epoch on it, trained once for the module (each test copies it)."""
    folder = tmp_path_factory.mktemp("trained")
    data = write_walk_file(folder / "walk.ndjson")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))
        patch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path_factory.mktemp("shipped")))
        assert main(_args(data, folder / "run")) == 0
    return data, folder / "run"


@pytest.fixture
def run_copy(one_run, tmp_path) -> tuple[Path, Path]:
    data, run = one_run
    shutil.copytree(run, tmp_path / "run")
    return data, tmp_path / "run"


def _one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err.rstrip("\n")


@pytest.mark.parametrize(
    ("damage", "why"),
    [
        ("random bytes", "UnpicklingError: Weights only load failed.)"),
        (
            "half a checkpoint",
            "RuntimeError: PytorchStreamReader failed reading zip archive: failed finding central "
            "directory.)",
        ),
    ],
)
def test_a_damaged_last_checkpoint_is_named_with_the_first_sentence_of_why(run_copy, capsys, damage, why):
    """torch's message ran on for lines (how to load untrusted files, what a miniz error may mean) and was
    cut at 160 characters, mid-sentence: "... Re-running `torch.)"."""
    data, out = run_copy
    last = out / "checkpoints" / "last.ckpt"
    whole = last.read_bytes()
    broken = random.Random(0).randbytes(5000) if damage == "random bytes" else whole[: len(whole) // 2]
    last.write_bytes(broken)
    capsys.readouterr()
    assert main([*_args(data, out, epochs=2), "--resume"]) == 2
    assert _one_line(capsys) == f"crowdmpc train: error: --resume: {last} {UNREADABLE}{why}"


def test_a_folder_in_place_of_the_last_checkpoint_is_named_a_folder(run_copy, capsys):
    """A resume said "last.ckpt does not exist", which it does, as a folder; a new run trained and saved its
    last checkpoint inside that folder, where no --resume reads it."""
    data, out = run_copy
    last = out / "checkpoints" / "last.ckpt"
    last.unlink()
    last.mkdir()
    capsys.readouterr()
    assert main([*_args(data, out, epochs=2), "--resume"]) == 2
    assert _one_line(capsys) == (
        f"crowdmpc train: error: --resume: {last} is a folder, not a checkpoint (nothing to resume in {out})"
    )
    assert main(_args(data, out)) == 2
    assert _one_line(capsys) == (
        f"crowdmpc train: error: --out {out}: its checkpoints/last.ckpt is a folder, not a checkpoint "
        "(remove it)"
    )


def test_an_out_folder_of_other_files_is_refused_and_left_alone(tmp_path, capsys):
    """`train --out` into a folder of the user's trained there, mixing the run's files with theirs, where
    `sweep --out` and `data prepare --out` refuse such a folder."""
    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "foreign"
    out.mkdir()
    (out / "notes.txt").write_text("hi\n")
    assert main(_args(data, out)) == 2
    assert _one_line(capsys) == (
        f"crowdmpc train: error: --out {out} holds files but no training run (train_settings.json or "
        "checkpoints/last.ckpt of `crowdmpc train`); a run would write among them: choose an empty or new "
        "folder"
    )
    assert [p.name for p in out.iterdir()] == ["notes.txt"]  # not even the run's lock


def test_a_folder_holding_only_a_gitkeep_is_trained_into_and_keeps_it(tmp_path, capsys):
    """A folder made ready for runs (runs/.gitkeep) was refused as holding "files but no training run"."""
    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "ready"
    out.mkdir()
    (out / ".gitkeep").write_text("")
    assert main(_args(data, out)) == 0
    assert (out / ".gitkeep").read_text() == "" and (out / "train_settings.json").is_file()


def test_an_empty_name_is_refused_not_taken_for_none(tmp_path, capsys):
    """`--name ''` (an unset shell variable) trained under the default name."""
    data = write_walk_file(tmp_path / "walk.ndjson")
    assert main([*_args(data, tmp_path / "run"), "--name", ""]) == 2
    assert "--name '' is not allowed" in _one_line(capsys)
    assert not (tmp_path / "run").exists()


def test_an_empty_out_and_a_run_stopped_before_its_first_checkpoint_are_trained_into(run_copy, tmp_path):
    """What stays accepted: an empty folder, and a run's folder with no last.ckpt yet (its settings, logs
    and a file the user put there), which a new run replaces, then resumes."""
    data, out = run_copy
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(_args(data, empty)) == 0
    shutil.rmtree(out / "checkpoints")
    for written in out.glob("vanilla_lstm_custom.*"):
        written.unlink()
    (out / "notes.txt").write_text("the user's\n")
    assert main(_args(data, out)) == 0
    assert main([*_args(data, out, epochs=2), "--resume"]) == 0
    assert (out / "notes.txt").read_text() == "the user's\n"


def test_only_the_first_sentence_of_a_long_error_is_shown_and_never_a_cut_one():
    from pipelines.commands.train_resume import _first_sentence

    assert _first_sentence(EOFError()) == "EOFError"
    assert _first_sentence(EOFError("Ran out of input")) == "EOFError: Ran out of input"
    long = RuntimeError("Bad header in v2.6 file. See `torch.load` for more.\nDetails follow.")
    assert _first_sentence(long) == "RuntimeError: Bad header in v2.6 file."
    assert _first_sentence(ValueError("x" * 300 + ". more")) == "ValueError"


def test_a_resume_of_a_run_that_never_started_says_there_is_nothing_to_resume(tmp_path, capsys):
    """Without --epochs, a resume of an --out holding nothing (a run killed before it wrote) said the folder
    "does not record how many epochs it trains in all (a run started before the count was kept)"."""
    out = tmp_path / "never"
    assert main(["train", "--model", "vanilla_lstm", "--resume", "--out", str(out)]) == 2
    last = out / "checkpoints" / "last.ckpt"
    assert _one_line(capsys) == (
        f"crowdmpc train: error: --resume: {last} does not exist (nothing to resume in {out})"
    )


def test_weights_that_do_not_fit_the_net_are_named_before_lightning_loads_them(run_copy, capsys):
    """A hand-edited last.ckpt (or a plugin net given a layer since the run started) ended the resume in
    Lightning's traceback of load_state_dict."""
    import torch

    data, out = run_copy
    last = out / "checkpoints" / "last.ckpt"
    checkpoint = torch.load(last, map_location="cpu", weights_only=True)
    first = next(iter(checkpoint["state_dict"]))
    shape = "x".join(map(str, checkpoint["state_dict"][first].shape))
    checkpoint["state_dict"][first] = torch.zeros(3, 3)
    checkpoint["state_dict"]["net.extra.weight"] = torch.zeros(2)
    torch.save(checkpoint, last)
    capsys.readouterr()
    assert main([*_args(data, out, epochs=2), "--resume"]) == 2
    assert _one_line(capsys) == (
        f"crowdmpc train: error: --resume: {last}'s weights do not fit the net this run builds "
        f"(net.extra.weight not in the net; {first} 3x3 in the file, {shape} in the net): its code changed "
        "since the run started, or the file was edited; train it anew with another --out"
    )
    del checkpoint["state_dict"][first], checkpoint["state_dict"]["net.extra.weight"]
    torch.save(checkpoint, last)
    assert main([*_args(data, out, epochs=2), "--resume"]) == 2
    assert f"({first} missing)" in _one_line(capsys)


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("name", "../../escaped", "its name '../../escaped' is not allowed: use 1 to 64 letters"),
        ("seed", -1, "--seed must be in 0..4294967295, got -1, taken from"),
    ],
)
def test_a_damaged_settings_file_is_named_before_training_and_nothing_is_written_outside(
    run_copy, capsys, key, value, message
):
    """Its "name" was taken unchecked: the run trained to its end, then made a folder two levels above --out
    ('r6/../../escaped.part'); a "seed" of -1 was refused as "--seed must be ...", an option never typed."""
    import json

    data, out = run_copy
    settings = out / "train_settings.json"
    document = json.loads(settings.read_text(encoding="utf-8"))
    settings.write_text(json.dumps({**document, key: value}), encoding="utf-8")
    around = sorted(p.name for p in out.parent.parent.iterdir())
    before = sorted(p.name for p in (out / "checkpoints").iterdir())
    capsys.readouterr()
    assert main([*_args(data, out, epochs=2), "--resume"]) == 2
    line = _one_line(capsys)
    assert line.startswith("crowdmpc train: error: --resume: ") and message in line, line
    assert line.endswith(f"{settings}; the file is damaged") or line.startswith(
        f"crowdmpc train: error: --resume: {settings}: "
    ), line
    assert sorted(p.name for p in out.parent.parent.iterdir()) == around
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == before  # no epoch trained


def test_a_finished_run_without_its_checkpoints_is_not_trained_over(run_copy, capsys):
    """A finished run whose checkpoints/ was removed (to save space) passed as a run stopped before its first
    checkpoint: a second train into it replaced its NAME.pt, NAME.json and metrics without a word."""
    data, out = run_copy
    shutil.rmtree(out / "checkpoints")
    written = {p.name: p.read_bytes() for p in out.glob("vanilla_lstm_custom.*")}
    assert main([*_args(data, out), "--seed", "7"]) == 2
    assert _one_line(capsys) == (
        f"crowdmpc train: error: {out} holds a finished run's vanilla_lstm_custom.metrics.json, "
        "vanilla_lstm_custom.pt but no checkpoints/last.ckpt to resume; a new run would replace them: choose "
        "another --out, or remove them"
    )
    assert {p.name: p.read_bytes() for p in out.glob("vanilla_lstm_custom.*")} == written


def test_a_folder_of_ones_own_weights_is_no_finished_run(tmp_path, run_copy, capsys):
    """A folder of the user's own files with a .pt among them was refused as "a finished run's" weights, to
    be removed; and a finished run from before runs kept their settings, its checkpoints/ removed, was told to
    remove its NAME.pt and metrics, after which it was still refused as no training run."""
    data, run = run_copy
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "weights.pt").write_bytes(b"mine")
    shutil.rmtree(run / "checkpoints")
    (run / "train_settings.json").unlink()
    for out in (mine, run):
        assert main([*_args(data, out), "--seed", "7"]) == 2
        assert _one_line(capsys) == (
            f"crowdmpc train: error: --out {out} holds files but no training run (train_settings.json or "
            "checkpoints/last.ckpt of `crowdmpc train`); a run would write among them: choose an empty or "
            "new folder"
        )
    assert [p.name for p in mine.iterdir()] == ["weights.pt"]
