"""``crowdmpc train``, ``zoo`` and ``export`` from the command line, on a dataset the test writes itself."""

from __future__ import annotations

import collections
import json
import re
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from pipelines.cli import main
from pipelines.errors import PipelineError
from predictors.registry import available, load_predictor
from predictors.zoo import user_zoo_dir
from tests.predictors.samples import walk_scene_records, write_lines, write_walk_file
from tests.read_only import file_size_limit


@pytest.fixture(autouse=True)
def _private_dirs(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))
    monkeypatch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path_factory.mktemp("shipped")))  # an empty one


@pytest.fixture
def trained(tmp_path):
    """One epoch of soft-pooling Social-LSTM on the walk scenes, as `crowdmpc train` writes it."""
    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    args = [
        "train",
        "--model",
        "social_lstm",
        "--pooling",
        "soft",
        "--train",
        str(data),
        "--val",
        str(data),
        "--test",
        str(data),
        "--epochs",
        "1",
        "--batch-size",
        "2",
        "--out",
        str(out),
        "--name",
        "walker",
        "--no-progress",
    ]
    assert main(args) == 0
    return out, args


def test_train_writes_checkpoint_pair_logs_and_metrics(trained):
    out, _ = trained
    config = json.loads((out / "walker.json").read_text())
    assert config["model"] == "social_lstm" and config["net"]["pooling"] == "soft"
    assert config["class"] == "LearnedPredictor"  # informational: the model kind decides
    summary = json.loads((out / "walker.metrics.json").read_text())
    assert set(summary["metrics"]) == {"val", "test"} and summary["metrics"]["test"]["scenes"] == 2
    assert summary["training_data"]["files"]["train"] == summary["training_data"]["files"]["val"]
    assert "commit" in summary["code"] and summary["code"]["torch"].startswith("2.13")
    assert (out / "checkpoints" / "last.ckpt").is_file()
    (log,) = (out / "csv").glob("version_*/metrics.csv")
    # one batch an epoch, fewer than log_every_n_steps: the epoch's mean loss is logged all the same
    assert "train_loss_epoch" in log.read_text().splitlines()[0].split(",")
    assert list((out / "tensorboard").glob("version_*/events.out.tfevents.*"))


def test_train_is_seeded(trained, tmp_path):
    import torch

    out, args = trained
    again = tmp_path / "again"
    assert main([*[str(again) if a == str(out) else a for a in args]]) == 0
    first = torch.load(out / "walker.pt", weights_only=True)
    second = torch.load(again / "walker.pt", weights_only=True)
    assert all(torch.equal(first[k], second[k]) for k in first)


def test_train_refuses_to_overwrite_and_resumes(trained, capsys):
    out, args = trained
    assert main(args) == 2
    assert "already holds a training run; pass --resume" in capsys.readouterr().err
    more = [a if a != "1" else "2" for a in args]  # --epochs 2: one more epoch from last.ckpt
    assert main([*more, "--resume"]) == 0
    assert json.loads((out / "walker.metrics.json").read_text())["training"]["epochs"] == 2


def test_a_resume_by_other_code_says_so_and_one_by_the_same_code_does_not(trained, capsys):
    """train_settings.json recorded no code, so a run begun by one commit and resumed by another trained on
    without a word, and its metrics file named the resuming commit only."""
    out, args = trained
    settings_file = out / "train_settings.json"
    settings = json.loads(settings_file.read_text())
    assert (
        settings["code"]["commit"] == json.loads((out / "walker.metrics.json").read_text())["code"]["commit"]
    )
    capsys.readouterr()
    assert main([*[a if a != "1" else "2" for a in args], "--resume"]) == 0
    assert "note: --resume" not in capsys.readouterr().err
    settings["code"]["commit"] = "0123456789abcdef"
    settings_file.write_text(json.dumps(settings))
    assert main([*[a if a != "1" else "3" for a in args], "--resume"]) == 0
    err = capsys.readouterr().err
    assert f"note: --resume: {out} was started by other code (commit 0123456789ab -> " in err
    del settings["code"]
    settings_file.write_text(json.dumps(settings))
    assert main([*[a if a != "1" else "4" for a in args], "--resume"]) == 0
    assert "(code not recorded -> commit " in capsys.readouterr().err


def test_a_second_train_into_an_out_a_run_holds_is_refused(tmp_path, capsys):
    """A run's folder has no last.ckpt until its first epoch ends: a second train started meanwhile (two
    terminals) passed the 'already holds a training run' check, trained into the same folder and left one
    run's train_settings.json beside the other's last.ckpt, a run no --resume takes."""
    import fcntl

    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    out.mkdir()
    args = ["train", "--model", "vanilla_lstm", "--train", str(data), "--val", str(data)]
    args += ["--epochs", "1", "--out", str(out), "--name", "walker", "--no-progress"]
    with open(
        out / ".train.lock", "w", encoding="utf-8"
    ) as held:  # as the running train holds it (another open file)
        fcntl.flock(held, fcntl.LOCK_EX)
        assert main(args) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc train: error: another crowdmpc train is writing to {out}; wait for it or choose another "
        "--out\n"
    )
    assert sorted(p.name for p in out.iterdir()) == [".train.lock"]  # nothing of a run written
    assert main(args) == 0  # once the other run has ended


def test_a_failed_train_leaves_the_out_it_found_as_it_was(tmp_path, monkeypatch, capsys):
    """A train stopped in an empty --out that existed (Ctrl-C as it started fitting) left its .train.lock
    there, and a sweep --out then refused that folder as one holding files."""
    from pipelines.commands import train_fit
    from pipelines.experiments.sweep_folder import check_sweep_directory

    def interrupted(*_args, **_kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(train_fit, "run_training", interrupted)
    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    out.mkdir()
    args = ["train", "--model", "vanilla_lstm", "--train", str(data), "--val", str(data), "--out", str(out)]
    assert main([*args, "--epochs", "1", "--no-progress"]) == 130
    assert list(out.iterdir()) == []
    check_sweep_directory(out)  # refuses nothing


@pytest.mark.parametrize("planted", ["fifo", "directory"])
def test_a_lock_planted_as_no_regular_file_is_named_so(planted, tmp_path, capsys):
    """The open's own error was the message: "(No such device or address)" for a FIFO, "(Is a directory)"
    for a folder, where a lock that opens but is no regular file is "(not a regular file); remove it"."""
    import os

    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    out.mkdir()
    lock = out / ".train.lock"
    if planted == "fifo":
        os.mkfifo(lock)
    else:
        lock.mkdir()
    args = ["train", "--model", "vanilla_lstm", "--train", str(data), "--val", str(data), "--out", str(out)]
    assert main([*args, "--epochs", "1", "--no-progress"]) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc train: error: {lock}: cannot lock the training run (not a regular file); remove it\n"
    )


def test_a_lock_on_a_file_system_that_does_not_lock_is_one_line(tmp_path, monkeypatch, capsys):
    """On an NFS mount without its lock daemon flock fails with ENOLCK ("No locks available"): every
    ``locked`` (a training run, a zoo's manifest, a data preparation) ended in that OSError's traceback."""
    import errno
    import fcntl
    import os

    def no_locks(fd, operation):
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))

    monkeypatch.setattr(fcntl, "flock", no_locks)
    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    args = ["train", "--model", "vanilla_lstm", "--train", str(data), "--val", str(data), "--out", str(out)]
    assert main([*args, "--epochs", "1", "--no-progress"]) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc train: error: {out / '.train.lock'}: cannot lock the training run (No locks available: "
        "its file system does not lock files; an NFS mount without its lock daemon?)\n"
    )


def test_a_train_ended_by_sigterm_is_interrupted_not_a_success(tmp_path, monkeypatch, capsys):
    """Lightning ends a fit that SIGTERM (``kill``) stopped with SystemExit(0): train exited 0, silently,
    with no weights written, so ``crowdmpc train ... && crowdmpc zoo add ...`` went on."""
    import os
    import signal

    from predictors.training import PredictorModule

    started = PredictorModule.on_train_epoch_start

    def killed(self):
        started(self)
        os.kill(os.getpid(), signal.SIGTERM)  # Lightning's handler only notes it; its loop stops at once

    monkeypatch.setattr(PredictorModule, "on_train_epoch_start", killed)
    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    args = ["train", "--model", "vanilla_lstm", "--train", str(data), "--val", str(data)]
    assert main([*args, "--epochs", "3", "--out", str(out), "--name", "walker", "--no-progress"]) == 143
    assert capsys.readouterr().err.endswith("crowdmpc train: interrupted\n")
    assert not (out / "walker.pt").exists()


def test_a_resume_reads_the_runs_settings_once(trained, monkeypatch):
    """The resume's loss, its check of the settings and its note on the code each read train_settings.json:
    three reads of one file. It is read once and handed to each."""
    out, args = trained
    reads, real = [], Path.read_text

    def counted(path, *a, **k):
        if path.name == "train_settings.json":
            reads.append(path)
        return real(path, *a, **k)

    monkeypatch.setattr(Path, "read_text", counted)
    assert main([*[a if a != "1" else "2" for a in args], "--resume"]) == 0
    assert reads == [out / "train_settings.json"]


def test_resume_refuses_to_train_no_epoch(trained, capsys):
    """--resume with --epochs at or below the epochs last.ckpt has finished trained nothing, yet wrote
    NAME.pt, NAME.json and the metrics again with the smaller count. The same count still finishes a run
    that stopped before its metrics were written."""
    out, args = trained

    def resume(epochs: str) -> int:
        at = args.index("--epochs") + 1
        return main([*args[:at], epochs, *args[at + 1 :], "--resume"])

    assert resume("2") == 0
    outputs = [out / f"walker{suffix}" for suffix in (".pt", ".json", ".metrics.json")]
    before = [p.read_bytes() for p in outputs]
    capsys.readouterr()
    for epochs in ("1", "2"):
        assert resume(epochs) == 2
        err = capsys.readouterr().err
        assert err == (
            f"crowdmpc train: error: --resume: {out} has trained 2 epochs already; --epochs {epochs} would "
            "train none (give more than 2 to continue it)\n"
        )
    assert [p.read_bytes() for p in outputs] == before
    outputs[2].unlink()  # a run that stopped after training, before its metrics
    assert resume("2") == 0
    assert json.loads(outputs[2].read_text())["training"]["epochs"] == 2


class Interrupted(BaseException):
    """A Ctrl-C or a kill at that instant (BaseException, as KeyboardInterrupt: no handler catches it)."""


def resumed_to(args: list[str], epochs: str) -> list[str]:
    at = args.index("--epochs") + 1
    return [*args[:at], epochs, *args[at + 1 :], "--resume"]


def test_a_resume_interrupted_in_its_evaluation_is_finished_by_resume(trained, tmp_path, monkeypatch, capsys):
    """Stopped while evaluating its new weights, a resumed run left them beside the metrics of its earlier,
    shorter run: `zoo add` took those, and the same --resume then refused ("trained 2 epochs already")."""
    from pipelines.commands import train_report

    out, args = trained
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "zoo"))

    def interrupted(*_args, **_kwargs):
        raise Interrupted

    with monkeypatch.context() as patched, pytest.raises(Interrupted):
        patched.setattr(train_report, "evaluate_splits", interrupted)
        main(resumed_to(args, "2"))
    assert not (out / "walker.metrics.json").exists()
    capsys.readouterr()
    assert main(["zoo", "add", str(out / "walker.pt")]) == 2
    assert "walker.metrics.json does not exist" in capsys.readouterr().err
    assert main(resumed_to(args, "2")) == 0
    assert json.loads((out / "walker.metrics.json").read_text())["training"]["epochs"] == 2
    assert main(["zoo", "add", str(out / "walker.pt")]) == 0
    # no temporary left behind; the run's lock stays, as the zoo's (removed, two runs could lock two files)
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [".train.lock"]


def test_the_median_epoch_time_of_an_even_count_is_the_mean_of_the_middle_two(trained, monkeypatch):
    """Epochs of 0.047 and 0.033 s: median 0.04 s; the upper middle time, which metrics.json and the closing
    line gave, read 0.05 s."""
    from pipelines.commands import train_report

    out, args = trained
    monkeypatch.setattr(train_report, "epoch_times_from_csv", lambda _log_dir: [0.047, 0.033])
    assert main(resumed_to(args, "2")) == 0
    summary = json.loads((out / "walker.metrics.json").read_text())
    assert summary["training"]["median_epoch_time_s"] == 0.04


def test_zoo_add_refuses_the_metrics_of_other_weights(trained, tmp_path, monkeypatch, capsys):
    """The metrics of a run's first epoch beside its resumed weights: told apart by the weights' sha256 the
    metrics record, and in a metrics file written before they did, by the epochs."""
    from predictors.hashing import sha256_file

    out, args = trained
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "zoo"))
    metrics = out / "walker.metrics.json"
    first = json.loads(metrics.read_text())
    assert first["weights_sha256"] == sha256_file(out / "walker.pt")
    assert main(resumed_to(args, "2")) == 0
    capsys.readouterr()
    metrics.write_text(json.dumps(first))
    assert main(["zoo", "add", str(out / "walker.pt")]) == 2
    assert "holds the metrics of weights with sha256" in capsys.readouterr().err
    old = ("weights_sha256", "config_sha256")  # a metrics file from before either was recorded
    metrics.write_text(json.dumps({k: v for k, v in first.items() if k not in old}))
    assert main(["zoo", "add", str(out / "walker.pt")]) == 2
    assert "holds the metrics of epochs 1, not of" in capsys.readouterr().err
    # a truncated weights file was told to finish its run with train --resume
    metrics.write_text(json.dumps(first))
    weights = out / "walker.pt"
    weights.write_bytes(weights.read_bytes()[:1500])
    assert main(["zoo", "add", str(weights)]) == 2
    err = capsys.readouterr().err
    assert f"{weights} is not the file `crowdmpc train` wrote" in err and "does not read as weights" in err
    assert "--resume" not in err


def test_the_data_record_names_every_file(tmp_path):
    """Files were recorded by bare name: --train d1/t.ndjson d2/t.ndjson recorded one of them, and the
    combined hash left the other out. Names are relative to the files' common directory now; one file, or
    files of one directory, keep their bare names, and a protocol's files their names under its root."""
    from pipelines.commands.train_report import data_record
    from predictors.hashing import sha256_file

    first = write_walk_file(tmp_path / "d1" / "t.ndjson")
    second = write_lines(tmp_path / "d2" / "t.ndjson", walk_scene_records())
    val = write_walk_file(tmp_path / "d1" / "v.ndjson")
    files = {"train": [first, second], "val": [val], "test": []}
    record = data_record(files, None, "custom")
    assert record["files"] == {
        "train": {"d1/t.ndjson": sha256_file(first), "d2/t.ndjson": sha256_file(second)},
        "val": {"v.ndjson": sha256_file(val)},
        "test": {},
    }
    first.write_text(first.read_text() + "\n")  # the hash covers both training files
    assert data_record(files, None, "custom")["sha256"] != record["sha256"]
    assert data_record({"train": [val], "val": [val], "test": []}, None, "custom")["files"]["train"] == {
        "v.ndjson": sha256_file(val)
    }
    under_root = data_record({"train": [first], "val": [second], "test": []}, tmp_path, "paper")
    assert list(under_root["files"]["train"]) == ["d1/t.ndjson"]
    assert list(under_root["files"]["val"]) == ["d2/t.ndjson"]
    # loo: files under the protocol's root and files elsewhere; those elsewhere keep their bare names (the
    # common directory of all of them made the record depend on where the data and the cache sit)
    elsewhere = write_walk_file(tmp_path / "raw" / "zara.ndjson")
    mixed = data_record({"train": [first, elsewhere], "val": [], "test": []}, tmp_path / "d1", "loo")
    assert list(mixed["files"]["train"]) == ["t.ndjson", "zara.ndjson"]


def test_resume_refuses_other_settings_and_keeps_the_runs_name(trained, capsys):
    """The weights, optimiser and schedule resume from last.ckpt whatever the command says: a resume with
    another learning rate or net would write a NAME.json recording settings that never trained the weights.
    Without --name, the run's own name is kept (the default name would follow other options)."""
    out, args = trained
    more = [a if a != "1" else "2" for a in args]  # --epochs 2
    lr = [*more, "--lr", "0.05", "--seed", "7", "--resume"]
    assert main(lr) == 2
    err = capsys.readouterr().err
    assert (
        f"--resume: {out} was started with other settings (lr: run 0.001, now 0.05; seed: run 0, now 7)"
        in err
    )
    assert err.count("\n") == 1 and "Traceback" not in err
    hidden = [*more, "--net-config", '{"hidden_dim": 16}', "--resume"]
    assert main(hidden) == 2 and "net_config: run {" in capsys.readouterr().err
    unnamed = [a for i, a in enumerate(more) if a != "--name" and more[i - 1] != "--name"]
    assert main([*unnamed, "--resume"]) == 0
    assert sorted(p.name for p in out.glob("*.pt")) == ["walker.pt"]
    recorded = json.loads((out / "walker.json").read_text())
    assert recorded["training"]["optim"]["lr"] == 0.001 and recorded["training"]["epochs"] == 2


def test_resume_from_a_bad_or_foreign_last_checkpoint_is_one_line(trained, capsys):
    """A cut file, or one of another model (a run from before train_settings.json, so only the checkpoint
    can tell), failed inside Lightning with a traceback."""
    out, args = trained
    more = [*[a if a != "1" else "2" for a in args], "--resume"]
    last = out / "checkpoints" / "last.ckpt"
    whole = last.read_bytes()
    (out / "train_settings.json").unlink()
    vanilla = [a if a != "social_lstm" else "vanilla_lstm" for a in more]
    vanilla = [a for i, a in enumerate(vanilla) if a != "--pooling" and vanilla[i - 1] != "--pooling"]
    assert main(vanilla) == 2
    err = capsys.readouterr().err
    assert f'--resume: {last} was trained with another model (model: checkpoint "social_lstm"' in err
    last.write_bytes(whole[:1000])
    assert main(more) == 2
    err = capsys.readouterr().err
    assert f"--resume: {last} is not a readable Lightning checkpoint (" in err and err.count("\n") == 1


@pytest.mark.parametrize("settings_file", ["gone", "null", "[1, 2]"])
def test_resume_checks_the_checkpoints_own_settings_when_the_runs_file_is_gone(
    trained, capsys, settings_file
):
    """last.ckpt holds the optimiser's and the data's settings too: with train_settings.json deleted or
    damaged, a resume asking for another learning rate, seed or batch is still refused, in one line."""
    out, args = trained
    path = out / "train_settings.json"
    if settings_file == "gone":
        path.unlink()
    else:
        path.write_text(settings_file)
    more = [*[a if a != "1" else "2" for a in args], "--lr", "0.5", "--seed", "7", "--resume"]
    assert main(more) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    if settings_file == "gone":
        assert (
            "was trained with other settings (lr: checkpoint 0.001, now 0.5; seed: checkpoint 0, now 7)"
            in err
        )
    else:
        assert "is not a JSON object of settings" in err


def _without(args: list[str], *options: str) -> list[str]:
    """``args`` without each of ``options`` and its value."""
    return [a for i, a in enumerate(args) if a not in options and (i == 0 or args[i - 1] not in options)]


@pytest.mark.parametrize("settings_file", ["kept", "gone"])
def test_a_resume_goes_on_with_the_settings_it_leaves_out(trained, capsys, settings_file):
    """Every setting had to be typed again: a resume of the soft-pooling run at batch 2 without --pooling or
    --batch-size was refused (the default grid net, batch 8). Left out, each is the run's: from its settings
    file, or from its last.ckpt for a run from before that file."""
    out, args = trained
    left_out = ["--pooling", "--batch-size", "--name"]
    if settings_file == "gone":
        (out / "train_settings.json").unlink()
        left_out.remove("--name")  # the name is the settings file's alone
    lean = _without([a if a != "1" else "2" for a in args], *left_out)
    assert main([*lean, "--resume"]) == 0
    err = capsys.readouterr().err
    assert f"--resume: {out} goes on with the run's batch_size 2, its net config\n" in err
    recorded = json.loads((out / "walker.json").read_text())
    assert recorded["net"]["pooling"] == "soft" and recorded["training"]["epochs"] == 2
    assert recorded["training"]["batch_size"] == 2


def test_a_resume_typing_some_net_options_keeps_the_runs_others(trained, capsys):
    """--hidden-dim or --net-config typed alone on a resume was laid over the kind's defaults: the soft run
    resumed with its own hidden size 32 was refused as a grid net. Laid over the run's config now, the soft
    pooling left out goes on; a typed hidden size other than the run's is still refused, naming the net."""
    out, args = trained
    more = _without([a if a != "1" else "2" for a in args], "--pooling")  # --epochs 2
    assert main([*more, "--hidden-dim", "16", "--resume"]) == 2
    err = capsys.readouterr().err
    shown = 'net_config: run {"hidden_dim": 32}, now {"hidden_dim": 16}); '
    assert f"--resume: {out} was started with other settings ({shown}" in err and err.count("\n") == 1
    assert main([*more, "--net-config", '{"hidden_dim": 32}', "--resume"]) == 0
    assert f"--resume: {out} goes on with the run's net config\n" in capsys.readouterr().err
    recorded = json.loads((out / "walker.json").read_text())
    assert recorded["net"]["pooling"] == "soft" and recorded["net"]["hidden_dim"] == 32
    assert recorded["training"]["epochs"] == 2
    more = [*_without(more, "--epochs"), "--epochs", "3"]
    assert main([*more, "--hidden-dim", "32", "--pooling", "soft", "--resume"]) == 0  # as the run's
    assert "goes on with the run's" not in capsys.readouterr().err


def test_training_prints_no_advertising_nor_upstream_deprecations(tmp_path, capfd):
    """Lightning's litlogger/litmodels tips and its use of a torch API that torch 2.13 deprecates are
    nothing a user of `crowdmpc train` can act on; they are left out, the run's own lines stay."""
    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    args = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--epochs", "1"]
    assert main([*args, "--out", str(tmp_path / "run"), "--no-progress"]) == 0
    out, err = capfd.readouterr()
    assert "Tip" not in out + err and "LeafSpec" not in out + err
    assert "add to the zoo with" in out


@pytest.mark.parametrize("folder", ["checkpoints", "csv", "tensorboard"])
def test_a_file_in_place_of_one_of_the_runs_folders_is_refused_before_the_run(tmp_path, capsys, folder):
    """A file where Lightning makes its checkpoints/, csv/ or tensorboard/ folder ended the run in a
    FileExistsError traceback from makedirs (csv/, after the data was read): one line now, nothing written."""
    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    out = tmp_path / "run"
    out.mkdir()
    (out / folder).write_text("a file\n")
    args = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--epochs", "1"]
    assert main([*args, "--out", str(out), "--no-progress"]) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc train: error: --out {out}: its {folder} is not a directory (remove it)\n"
    )
    assert sorted(p.name for p in out.iterdir()) == [folder]


def test_a_data_file_named_twice_in_a_split_is_refused(tmp_path, monkeypatch, capsys):
    """--train walk.ndjson walk.ndjson trained on its scenes twice, and recorded the same training data (the
    file once, the same sha256) as a run trained on it once, with other weights: refused in one line."""
    write_walk_file(tmp_path / "walk.ndjson")
    monkeypatch.chdir(tmp_path)
    args = ["train", "--model", "vanilla_lstm", "--epochs", "1", "--no-progress", "--out", "run"]
    assert main([*args, "--train", "walk.ndjson", "walk.ndjson", "--val", "walk.ndjson"]) == 2
    assert capsys.readouterr().err == (
        "crowdmpc train: error: --train names walk.ndjson more than once; give each file once\n"
    )
    absolute = str(tmp_path / "walk.ndjson")
    assert main([*args, "--train", "walk.ndjson", "--val", "walk.ndjson", absolute]) == 2
    assert f"--val names {absolute} more than once (as walk.ndjson); give" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_train_parses_each_data_file_once(tmp_path, monkeypatch):
    """The check before training read the validation file as the evaluation reads it and again as the data
    module does, and the evaluation after training read the validation and test files once more: three
    parses of --val and two of --test. The check's parse now serves all three, with the same metrics."""
    import predictors.data.trajnet_io
    import predictors.data.windows
    import predictors.evaluate
    from predictors.checkpoint import load_checkpoint
    from predictors.data import validate
    from predictors.evaluate import evaluate

    real, parsed = validate.parse_ndjson, collections.Counter()

    def counting(path):
        parsed[Path(path).name] += 1
        return real(path)

    for module in (validate, predictors.data.trajnet_io, predictors.data.windows, predictors.evaluate):
        if getattr(module, "parse_ndjson", None) is real:
            monkeypatch.setattr(module, "parse_ndjson", counting)
    files = {split: write_walk_file(tmp_path / f"{split}.ndjson") for split in ("train", "val", "test")}
    for blank_lines, path in enumerate(files.values()):  # other bytes: each file its own disk-cache entry
        path.write_text(path.read_text() + "\n" * blank_lines)
    options = [a for split, path in files.items() for a in (f"--{split}", str(path))]
    out = tmp_path / "run"
    argv = ["train", "--model", "vanilla_lstm", *options, "--epochs", "1", "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    assert parsed == {"train.ndjson": 1, "val.ndjson": 1, "test.ndjson": 1}
    metrics = json.loads((out / "vanilla_lstm_custom.metrics.json").read_text())["metrics"]
    net = load_checkpoint(out / "vanilla_lstm_custom.pt")
    for split in ("val", "test"):
        scored = evaluate(net, [files[split]], progress=False)["overall"]
        assert metrics[split] == {k: v for k, v in scored.items() if v is not None}


def test_training_never_writes_through_a_link_planted_in_its_folder(tmp_path, capsys):
    """A train_settings.json link in --out had the run's settings written over the file it points to, and a
    csv/ link had Lightning's logs written into the folder it points to: the settings now replace the link,
    and a link in place of one of Lightning's folders is refused before the run."""
    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    outside, elsewhere, out = tmp_path / "outside.txt", tmp_path / "elsewhere", tmp_path / "run"
    outside.write_text("keep me\n")
    elsewhere.mkdir()
    out.mkdir()
    (out / "csv").symlink_to(elsewhere)
    args = [
        "train",
        "--model",
        "vanilla_lstm",
        "--train",
        data,
        "--val",
        data,
        "--epochs",
        "1",
        "--out",
        str(out),
    ]
    assert main([*args, "--no-progress"]) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc train: error: --out {out}: its csv is a symbolic link; crowdmpc does not write through "
        "one (remove it)\n"
    )
    (out / "csv").unlink()
    (out / "train_settings.json").symlink_to(outside)
    assert main([*args, "--no-progress"]) == 0
    assert outside.read_text() == "keep me\n" and list(elsewhere.iterdir()) == []
    settings = out / "train_settings.json"
    assert not settings.is_symlink() and json.loads(settings.read_text())["model"] == "vanilla_lstm"


def test_the_recorded_loss_is_the_one_trained(trained):
    """A Gaussian loss asked of a net with a point head trains on L2 (PredictorModule.model_step), and the
    checkpoint says so; soft-pooling Social-LSTM has a Gaussian head and keeps it."""
    out, _ = trained
    assert json.loads((out / "walker.json").read_text())["training"]["optim"]["loss"] == "gaussian"
    from predictors.optim_config import OptimConfig
    from predictors.training import make_module

    assert make_module("social_lstm", {"head": "point"}, OptimConfig()).trained_loss == "l2"
    assert make_module("social_lstm", None, OptimConfig(loss="l2")).trained_loss == "l2"
    assert make_module("social_lstm", None, OptimConfig()).trained_loss == "gaussian"
    assert make_module("social_gan", None, OptimConfig()).trained_loss == "variety+adversarial"


def test_a_loss_the_net_does_not_train_on_is_refused_and_the_default_follows_its_head(tmp_path, capsys):
    """--loss gaussian of a net with a point head, and any --loss of the GAN, were accepted and ignored (the
    run trained on L2, or on the GAN's own loss): refused in one line naming the model, before any run folder
    is made. With no --loss typed, the run trains on, and records, its head's: l2 for a point head."""
    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    base = ["train", "--train", data, "--val", data, "--epochs", "1", "--batch-size", "2", "--no-progress"]
    point = [*base, "--model", "social_lstm", "--net-config", '{"head": "point"}', "--name", "point"]
    assert main([*point, "--out", str(tmp_path / "point"), "--loss", "gaussian"]) == 2
    assert capsys.readouterr().err == (
        "crowdmpc train: error: --loss gaussian does not apply to social_lstm (its head_type is 'point': it "
        "trains on l2)\n"
    )
    assert main([*base, "--model", "social_gan", "--out", str(tmp_path / "gan"), "--loss", "l2"]) == 2
    assert capsys.readouterr().err == (
        "crowdmpc train: error: --loss does not apply to social_gan (a GAN: it trains on its variety + "
        "adversarial loss)\n"
    )
    assert not (tmp_path / "point").exists() and not (tmp_path / "gan").exists()
    assert main([*point, "--out", str(tmp_path / "point")]) == 0
    assert json.loads((tmp_path / "point" / "train_settings.json").read_text())["loss"] == "l2"
    assert json.loads((tmp_path / "point" / "point.json").read_text())["training"]["optim"]["loss"] == "l2"
    capsys.readouterr()
    assert main([*point, "--out", str(tmp_path / "point"), "--loss", "l2", "--epochs", "2", "--resume"]) == 0


def test_a_loss_the_net_does_not_train_on_is_refused_before_the_data_is_read(tmp_path, capsys):
    """The --loss check came after the data: with the protocol's files it prepared them first (40 s of
    output and a filled cache), here it named the missing data instead of the option."""
    missing = str(tmp_path / "no-data")
    assert main(["train", "--model", "social_gan", "--loss", "l2", "--data-dir", missing]) == 2
    assert capsys.readouterr().err == (
        "crowdmpc train: error: --loss does not apply to social_gan (a GAN: it trains on its variety + "
        "adversarial loss)\n"
    )


def test_a_run_recorded_before_the_loss_followed_the_head_resumes_with_its_own(tmp_path, capsys):
    """A point-head run started when --loss defaulted to gaussian recorded "gaussian" (and trained on L2):
    resumed with no --loss it keeps that record, settings file and last.ckpt alike, as a Gaussian-head run
    recorded "gaussian" does; typed, --loss gaussian is refused there too, and --loss l2 is the same run."""
    import torch

    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    out = tmp_path / "old"
    args = ["train", "--model", "social_lstm", "--net-config", '{"head": "point"}', "--train", data]
    args += ["--val", data, "--batch-size", "2", "--no-progress", "--name", "old", "--out", str(out)]
    assert main([*args, "--epochs", "1"]) == 0
    settings = out / "train_settings.json"
    settings.write_text(json.dumps({**json.loads(settings.read_text()), "loss": "gaussian"}))
    last = out / "checkpoints" / "last.ckpt"
    checkpoint = torch.load(last, map_location="cpu", weights_only=True)
    checkpoint["hyper_parameters"]["optim_config"]["loss"] = "gaussian"
    torch.save(checkpoint, last)
    capsys.readouterr()
    assert main([*args, "--epochs", "2", "--loss", "gaussian", "--resume"]) == 2
    assert "--loss gaussian does not apply to social_lstm" in capsys.readouterr().err
    assert main([*args, "--epochs", "2", "--resume"]) == 0
    assert json.loads(settings.read_text())["loss"] == "gaussian"
    assert json.loads((out / "old.json").read_text())["training"]["optim"]["loss"] == "l2"
    # typed, --loss l2 is what the run trained on: it was refused as another setting ("run gaussian, now l2")
    assert main([*args, "--epochs", "3", "--loss", "l2", "--resume"]) == 0
    assert json.loads(settings.read_text())["loss"] == "gaussian"


def test_a_run_of_relative_files_resumes_from_another_folder(tmp_path, monkeypatch, capsys):
    """last.ckpt kept the data files as typed: a run of --train walk.ndjson resumed from another folder with
    --train ../a/walk.ndjson, the same file, was refused as trained with other files (the relative name
    resolved in the new folder)."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    write_walk_file(tmp_path / "a" / "walk.ndjson")
    monkeypatch.chdir(tmp_path / "a")
    args = ["train", "--model", "vanilla_lstm", "--batch-size", "2", "--no-progress"]
    here = ["--train", "walk.ndjson", "--val", "walk.ndjson"]
    assert main([*args, *here, "--epochs", "1", "--out", "run"]) == 0
    monkeypatch.chdir(tmp_path / "b")
    capsys.readouterr()
    files = ["--train", "../a/walk.ndjson", "--val", "../a/walk.ndjson"]
    resumed = main([*args, *files, "--epochs", "2", "--out", "../a/run", "--resume"])
    assert resumed == 0, capsys.readouterr().err


@pytest.mark.parametrize("model", ["social_lstm", "social_gan"])
def test_a_resumed_run_ends_where_an_uninterrupted_one_does(tmp_path, model):
    """One epoch then --resume to two equals two epochs straight, weight for weight: the resumed epoch
    shuffles and rotates its scenes as epoch 1 does, not as epoch 0 (EpochShuffle), and the GAN draws the
    same noise (the checkpoint keeps torch's random state). Batches of one scene, so the order matters."""
    import torch

    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    files = ["--train", data, "--val", data, "--test", data]

    def train(out: str, epochs: int, *extra: str) -> dict:
        args = ["train", "--model", model, *files, "--batch-size", "1", "--step-size", "1", "--seed", "3"]
        assert main([*args, "--epochs", str(epochs), "--out", out, "--no-progress", *extra]) == 0
        return torch.load(tmp_path / out / "checkpoints" / "last.ckpt", weights_only=False)["state_dict"]

    straight = train(str(tmp_path / "straight"), 2)
    train(str(tmp_path / "resumed"), 1)
    resumed = train(str(tmp_path / "resumed"), 2, "--resume")
    assert straight.keys() == resumed.keys()
    assert all(torch.equal(straight[k], resumed[k]) for k in straight)


def test_a_moved_run_resumes_as_it_would_in_place(tmp_path, capsys):
    """Lightning keeps the absolute paths of a run's checkpoints: resumed after its folder was moved, the run
    forgot its best epoch (a worse later one became NAME.pt), wrote last-v1.ckpt beside an old last.ckpt, and
    read its best weights from the old folder. A best checkpoint missing from the folder, other than in the
    state a kill leaves (the next test), is refused."""
    import shutil

    import torch

    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    args = ["train", "--model", "social_lstm", "--train", data, "--val", data, "--batch-size", "1"]

    def train(out: str, epochs: int, *extra: str) -> int:
        return main([*args, "--lr", "0.5", "--epochs", str(epochs), "--out", out, "--no-progress", *extra])

    assert train(str(tmp_path / "in_place"), 2) == 0
    shutil.copytree(tmp_path / "in_place", tmp_path / "moved")
    (tmp_path / "in_place").rename(tmp_path / "away")  # nothing of the old folder to read while it resumes
    assert train(str(tmp_path / "moved"), 3, "--resume") == 0
    (tmp_path / "away").rename(tmp_path / "in_place")
    assert train(str(tmp_path / "in_place"), 3, "--resume") == 0

    def outcome(run: str) -> tuple:
        ckpts = tmp_path / run / "checkpoints"
        last = torch.load(ckpts / "last.ckpt", weights_only=False)
        weights = torch.load(tmp_path / run / "social_lstm_custom.pt", weights_only=True)
        return sorted(p.name for p in ckpts.iterdir()), last["epoch"], last["global_step"], weights

    in_place, moved = outcome("in_place"), outcome("moved")
    assert moved[:3] == in_place[:3]
    assert all(torch.equal(in_place[3][k], moved[3][k]) for k in in_place[3])

    # a run moved without its best (not the state a kill leaves): refused, as a worse epoch would take its
    # place as NAME.pt (a resume accepted it, and ended at val ADE 41.5 m where the run's best was 9.5 m)
    (best,) = (tmp_path / "moved" / "checkpoints").glob("best-*.ckpt")
    best.unlink()
    capsys.readouterr()
    assert train(str(tmp_path / "moved"), 4, "--resume") == 2
    assert f"names the run's checkpoint {best.name}, which is not in" in capsys.readouterr().err


def test_a_run_killed_between_its_new_best_and_last_checkpoint_resumes(tmp_path, monkeypatch):
    """Lightning saves an epoch's new best and removes the one before, then last.ckpt is written: a run
    killed between the two (kill -9 can) resumed from the last.ckpt of the epoch before, which names the
    removed file, and was refused ("put it back there"). It resumes as a run never killed ends."""
    import torch
    from lightning.pytorch.callbacks import ModelCheckpoint

    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    args = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--test", data]
    args += ["--batch-size", "1", "--epochs", "2", "--no-progress", "--out"]
    assert main([*args, str(tmp_path / "straight")]) == 0
    write_last = ModelCheckpoint._save_last_checkpoint

    def killed(self, trainer, candidates):
        if trainer.current_epoch == 1:
            raise Interrupted
        write_last(self, trainer, candidates)

    with monkeypatch.context() as patched, pytest.raises(Interrupted):
        patched.setattr(ModelCheckpoint, "_save_last_checkpoint", killed)
        main([*args, str(tmp_path / "killed")])
    ckpts = tmp_path / "killed" / "checkpoints"
    last = torch.load(ckpts / "last.ckpt", weights_only=False)
    (state,) = (v for k, v in last["callbacks"].items() if k.startswith("ModelCheckpoint"))
    assert last["epoch"] == 0 and not (ckpts / Path(state["best_model_path"]).name).exists()  # the case
    assert [p.name[:14] for p in ckpts.glob("best-*.ckpt")] == ["best-epoch=001"]  # the new best, kept
    assert main([*args, str(tmp_path / "killed"), "--resume"]) == 0

    def outcome(run: str) -> tuple:
        weights = torch.load(tmp_path / run / "vanilla_lstm_custom.pt", weights_only=True)
        metrics = json.loads((tmp_path / run / "vanilla_lstm_custom.metrics.json").read_text())
        listing = sorted(p.name for p in (tmp_path / run / "checkpoints").iterdir())
        return listing, metrics["training"]["best_checkpoint"], metrics["metrics"], weights

    straight, resumed = outcome("straight"), outcome("killed")
    assert resumed[:3] == straight[:3]
    assert straight[3].keys() == resumed[3].keys()
    assert all(torch.equal(straight[3][k], resumed[3][k]) for k in straight[3])


@pytest.mark.parametrize("mode", ["min", "max"])
def test_a_resumed_checkpoint_state_keeps_the_best_files_present(tmp_path, mode):
    """The best and k-th of a resumed state are those of the files still in the folder, as Lightning finds
    them; with none left there is no best (last.ckpt is read), and a state whose files are all there reads
    as it was written."""
    import torch

    from pipelines.commands.train_checkpoint import RunCheckpoint

    def state(*scores: float) -> dict:
        paths = [str(tmp_path / "old" / f"best-{i}.ckpt") for i in range(len(scores))]
        best_k = {path: torch.tensor(score) for path, score in zip(paths, scores, strict=True)}
        best = (min if mode == "min" else max)(best_k, key=best_k.__getitem__)
        held = {"best_k_models": best_k, "best_model_path": best, "best_model_score": best_k[best]}
        return {"dirpath": str(tmp_path / "old"), **held}

    def loaded(*scores: float, top_k: int = 3) -> RunCheckpoint:
        callback = RunCheckpoint(dirpath=tmp_path / "ckpts", monitor="val_ade", mode=mode, save_top_k=top_k)
        callback.load_state_dict(state(*scores))
        return callback

    (tmp_path / "ckpts").mkdir()
    for i in (1, 2):
        (tmp_path / "ckpts" / f"best-{i}.ckpt").write_bytes(b"")
    top = loaded(1.0, 2.0, 3.0, top_k=2)  # best-0, the best of all, is gone
    best, kth = ("best-1", "best-2") if mode == "min" else ("best-2", "best-1")
    assert (
        Path(top.best_model_path).name == f"{best}.ckpt"
        and Path(top.kth_best_model_path).name == f"{kth}.ckpt"
    )
    assert top.best_model_score == top.best_k_models[top.best_model_path] and len(top.best_k_models) == 2
    fewer = loaded(1.0, 2.0, 3.0)  # fewer than k: no k-th yet
    assert (fewer.kth_best_model_path, float(fewer.kth_value)) == (
        "",
        float("inf" if mode == "min" else "-inf"),
    )
    (tmp_path / "ckpts" / "best-0.ckpt").write_bytes(b"")
    assert loaded(1.0, 2.0, 3.0).best_model_path == str(
        tmp_path / "ckpts" / f"best-{0 if mode == 'min' else 2}.ckpt"
    )
    for path in (tmp_path / "ckpts").iterdir():
        path.unlink()
    gone = loaded(1.0)
    assert (gone.best_k_models, gone.best_model_path, gone.best_model_score) == ({}, "", None)


def test_last_checkpoint_is_every_epochs_own(tmp_path, capsys):
    """Lightning 2.6 wrote last.ckpt only at an epoch that was a new best: after worse epochs it held an
    earlier one, so a stopped run resumed from there and an ended run's --resume trained its epochs again."""
    import torch

    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    out = tmp_path / "run"
    args = ["train", "--model", "social_lstm", "--train", data, "--val", data, "--batch-size", "1"]
    args += ["--lr", "0.5", "--epochs", "3", "--out", str(out), "--no-progress"]
    assert main(args) == 0
    (best,) = (out / "checkpoints").glob("best-*.ckpt")
    assert not best.name.startswith("best-epoch=002")  # the last epoch is not the best: the case at issue
    last = torch.load(out / "checkpoints" / "last.ckpt", weights_only=False)
    assert (last["epoch"], last["global_step"]) == (2, 6)  # three epochs of two batches
    capsys.readouterr()
    assert main([*args, "--resume"]) == 2
    assert f"--resume: {out} has trained 3 epochs already" in capsys.readouterr().err


def test_limit_batches_trains_on_the_first_batches_and_is_recorded(tmp_path, capsys):
    """--limit-batches 1 with batches of one scene: one optimiser step an epoch where the walk file's two
    scenes give two; the checkpoint says so, a resume without the option goes on with it (it was refused:
    the option had to be typed again), and one typing another is refused."""
    import torch

    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    args = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--batch-size", "1"]

    def steps(out: str, *extra: str) -> int:
        assert main([*args, "--epochs", "2", "--out", str(tmp_path / out), "--no-progress", *extra]) == 0
        return torch.load(tmp_path / out / "checkpoints" / "last.ckpt", weights_only=False)["global_step"]

    assert (steps("all"), steps("limited", "--limit-batches", "1")) == (4, 2)
    assert steps("unlimited", "--limit-batches", "2") == 4  # the file's two batches an epoch: nothing cut

    def training(out: str) -> dict:
        (weights,) = (tmp_path / out).glob("*.pt")
        return json.loads(weights.with_suffix(".json").read_text())["training"]

    assert training("limited")["limit_batches"] == 1 and "limit_batches" not in training("all")
    # as the whole run to the bit, not a quick check (zoo add said "trained on 100000 batches an epoch")
    assert "limit_batches" not in training("unlimited")
    assert training("all")["pred_len"] == 12  # what the MPC's horizon note compares with
    capsys.readouterr()
    resumed = [*args, "--epochs", "3", "--out", str(tmp_path / "limited"), "--no-progress", "--resume"]
    assert main([*resumed, "--limit-batches", "2"]) == 2
    assert "limit_batches: run 1, now 2" in capsys.readouterr().err
    assert main(resumed) == 0
    assert (
        f"--resume: {tmp_path / 'limited'} goes on with the run's limit_batches 1" in capsys.readouterr().err
    )
    assert (
        torch.load(tmp_path / "limited" / "checkpoints" / "last.ckpt", weights_only=False)["global_step"] == 3
    )


def test_zoo_add_list_show_verify_export_and_hash_refusal(trained, tmp_path, capsys):
    out, _ = trained
    assert main(["zoo", "add", str(out / "walker.pt")]) == 0
    assert "walker" in available()
    capsys.readouterr()
    assert main(["zoo", "list"]) == 0
    listing = capsys.readouterr().out
    assert "walker" in listing and "social_lstm" in listing
    assert main(["zoo", "show", "walker"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["training_data"]["sha256"]
    # the code that trained it, as its metrics file recorded it (the entry kept the seed, not the commit)
    assert shown["training"]["code"] == json.loads((out / "walker.metrics.json").read_text())["code"]
    assert main(["zoo", "verify"]) == 0
    assert "walker (user): ok\n1 of 1 entries ok" in capsys.readouterr().out

    casadi_file = tmp_path / "walker.casadi"
    assert (
        main(
            [
                "export",
                "walker",
                "--out",
                str(casadi_file),
                "--humans",
                "2",
                "--robots",
                "1",
                "--horizon",
                "3",
            ]
        )
        == 0
    )
    function = ca.Function.load(str(casadi_file))
    predictor = load_predictor("walker")
    history = np.stack([np.array([[0.4 * t, 0.0], [0.4 * t, 0.6], [1.0, 0.3 * t]]) for t in range(9)])
    mask = np.ones((9, 3), dtype=bool)  # the 9 steps walker reads (obs_len)
    plan = np.array([[[1.0, 2.4]], [[1.0, 2.7]], [[1.0, 3.0]]])
    np.testing.assert_allclose(
        np.asarray(function(predictor.encode(history, mask, np.array([0, 1])), plan.ravel())).reshape(
            3, 2, 2
        ),
        predictor.rollout(history, mask, plan, np.array([0, 1])),
        rtol=0,
        atol=1e-6,
    )

    zoo_dir = user_zoo_dir()
    data = bytearray((zoo_dir / "walker.pt").read_bytes())
    data[-10] ^= 0x01
    (zoo_dir / "walker.pt").write_bytes(bytes(data))
    assert main(["zoo", "verify"]) == 1
    assert "walker.pt has sha256" in capsys.readouterr().out
    assert main(["export", "walker", "--out", str(casadi_file)]) == 2
    assert "the manifest expects" in capsys.readouterr().err


def test_unknown_names_and_bad_options_are_one_line_errors(capsys):
    assert main(["export", "no_such_model", "--out", "x.casadi"]) == 2
    assert "unknown predictor 'no_such_model'; choose from" in capsys.readouterr().err
    assert main(["zoo", "show", "nope"]) == 2
    assert main(["train", "--model", "vanilla_lstm", "--pooling", "soft", "--train", "a", "--val", "b"]) == 2
    assert "--pooling does not apply to vanilla_lstm" in capsys.readouterr().err


def test_unreadable_checkpoint_files_are_one_line_errors(tmp_path, capsys):
    weights = tmp_path / "bad.pt"
    config = {
        "format": "crowdmpc-predictor",
        "class": "SocialLSTMPredictor",
        "model": "social_lstm",
        "net": {},
    }
    (tmp_path / "bad.json").write_text(json.dumps(config))
    (tmp_path / "bad.metrics.json").write_text("{}")
    for content in (b"", b"not a torch file\n"):  # torch raises EOFError / UnpicklingError for these
        weights.write_bytes(content)
        assert main(["zoo", "add", str(weights)]) == 2
        assert "bad.pt: not a state_dict of tensors" in capsys.readouterr().err

    (tmp_path / "bad.json").write_text(json.dumps({**config, "net": {"hidden_dim": "32"}}))
    assert main(["zoo", "add", str(weights)]) == 2
    assert "holds a value of the wrong type" in capsys.readouterr().err

    (tmp_path / "bad.metrics.json").write_text("{not json")
    assert main(["zoo", "add", str(weights)]) == 2
    assert "bad.metrics.json: not valid JSON" in capsys.readouterr().err

    assert main(["export", "constant_velocity", "--out", str(tmp_path)]) == 2
    assert "is a directory" in capsys.readouterr().err

    # missing weights are named as such, with or without the metrics beside them
    for extra in ([], ["--metrics", str(tmp_path / "bad.metrics.json")]):
        assert main(["zoo", "add", str(tmp_path / "nosuch.pt"), *extra]) == 2
        assert f"{tmp_path / 'nosuch.pt'} is not a file; give the weights" in capsys.readouterr().err


def test_test_files_without_train_and_val_are_refused(tmp_path, capsys):
    path = tmp_path / "t.ndjson"
    write_walk_file(path)
    assert main(["train", "--model", "vanilla_lstm", "--test", str(path), "--out", str(tmp_path / "o")]) == 2
    assert "--test goes with --train and --val" in capsys.readouterr().err


def test_protocol_options_with_explicit_files_are_refused(tmp_path, monkeypatch, capsys):
    """--protocol, --dataset and --data-dir choose the prepared files that --train/--val replace: given with
    them they were ignored without a word. $CROWDMPC_DATA is no option typed: such a run still trains."""
    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    args = [
        "train",
        "--model",
        "vanilla_lstm",
        "--train",
        data,
        "--val",
        data,
        "--epochs",
        "1",
        "--no-progress",
    ]
    for given in (["--protocol", "paper"], ["--dataset", "biwi_hotel"], ["--data-dir", str(tmp_path)]):
        assert main([*args, *given, "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert f"error: {given[0]} does not go with --train/--val (explicit files replace" in err
        assert err.count("\n") == 1 and not (tmp_path / "o").exists()
    assert main([*args, "--protocol", "loo", "--data-dir", "/nonexistent", "--out", str(tmp_path / "o")]) == 2
    assert "error: --protocol and --data-dir do not go with --train/--val" in capsys.readouterr().err
    monkeypatch.setenv("CROWDMPC_DATA", str(tmp_path / "nonexistent"))
    assert main([*args, "--out", str(tmp_path / "o")]) == 0


def test_an_export_that_cannot_be_written_fails_and_keeps_the_earlier_one(tmp_path, capsys):
    """CasADi's save ignores write errors and writes in place: on a full disk (here ``ulimit -f``) export said
    "wrote" with status 0 over a cut file, the earlier export destroyed. It now writes beside it, loads that
    back, and only then renames it over; a device is refused (the rename would replace the node)."""
    out = tmp_path / "cv.casadi"
    assert main(["export", "constant_velocity", "--out", str(out), "--humans", "1", "--horizon", "1"]) == 0
    earlier = out.read_bytes()
    capsys.readouterr()
    with file_size_limit(len(earlier) + 512):  # the default sizes take several kB
        code = main(["export", "constant_velocity", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err
    assert f"--out {out}: could not write it" in err and "an earlier file there is unchanged" in err
    assert out.read_bytes() == earlier and sorted(p.name for p in tmp_path.iterdir()) == ["cv.casadi"]
    assert main(["export", "constant_velocity", "--out", "/dev/full"]) == 2
    assert "--out /dev/full is not a regular file" in capsys.readouterr().err


def test_export_replaces_an_earlier_export_but_no_other_file(tmp_path, capsys):
    """A mistyped --out replaced a README with CasADi's bytes; like --json and --plot, export now replaces
    only an empty file or its own kind (a CasADi function file)."""
    readme = tmp_path / "README.md"
    readme.write_text("# notes\n")
    assert main(["export", "constant_velocity", "--out", str(readme)]) == 2
    err = capsys.readouterr().err
    assert f"--out {readme}: the file exists and is not a CasADi function file" in err
    assert readme.read_text() == "# notes\n"
    out = tmp_path / "cv.casadi"
    assert main(["export", "constant_velocity", "--out", str(out)]) == 0
    first = out.read_bytes()
    assert main(["export", "constant_velocity", "--out", str(out), "--humans", "5"]) == 0
    assert out.read_bytes() != first  # the earlier export replaced by the new one
    empty = tmp_path / "empty.casadi"
    empty.touch()
    assert main(["export", "constant_velocity", "--out", str(empty)]) == 0


def test_evaluate_help_says_what_its_columns_are(capsys):
    """`evaluate` prints ADE, FDE, Col-I and Col-II; its help named the protocols but none of the metrics
    (docs/results.md's table neither): Col-I and Col-II were defined in data/README.md alone."""
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    metrics = capsys.readouterr().out.split("metrics (")[1]
    for line in ("ADE, FDE     average and final displacement error", "Col-I        % of scenes", "Col-II"):
        assert line in metrics, line
    assert "prediction collides with a neighbour's prediction" in metrics and "true path" in metrics


def test_a_save_stopped_by_a_kill_leaves_no_staging_folder_past_the_next_run(trained):
    """train writes NAME.pt and NAME.json into a staging folder in --out (.NAME.XXXXXXXX.part) and renames
    them out of it; a kill -9 or SIGTERM there (no finally runs) left the folder, with a copy of the
    weights, through every later run. The next save into --out, which holds the run's lock, removes it."""
    out, args = trained
    killed = out / ".walker.k1ll3d_0.part"
    killed.mkdir()
    (killed / "walker.pt").write_bytes(b"weights of the killed save")
    other = out / ".walker.part"  # not a staging folder's name: not ours to remove
    other.mkdir()
    epochs = args.index("--epochs") + 1
    assert main([*args[:epochs], "2", *args[epochs + 1 :], "--resume"]) == 0
    assert not killed.exists() and other.is_dir()


@pytest.mark.parametrize("name", ["SIGTERM", "SIGINT"])
def test_an_interrupted_training_prints_the_interrupt_alone(name, tmp_path, monkeypatch, capfd):
    """`kill` during a fit: Lightning's own SIGTERM handler logged "[rank: 0] Received SIGTERM: 15" above the
    CLI's line; and Ctrl-C or `kill` alike, its interrupt clause logged a blank line and "Detected
    KeyboardInterrupt, attempting graceful shutdown ..." there (README: the command's one line)."""
    import os
    import signal

    from predictors.data.datamodule import TrajnetDataModule

    sig = getattr(signal, name)
    loader = TrajnetDataModule.train_dataloader

    def killed(self):
        os.kill(os.getpid(), sig)  # SIGTERM under Lightning's handler, which calls the CLI's after its own
        return loader(self)

    monkeypatch.setattr(TrajnetDataModule, "train_dataloader", killed)
    # as a shell starts it: SIGTERM's default action, Python's own Ctrl-C handler (neither ignored)
    saved = signal.signal(sig, signal.SIG_DFL if sig == signal.SIGTERM else signal.default_int_handler)
    try:
        data = str(write_walk_file(tmp_path / "walk.ndjson"))
        args = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--epochs", "1"]
        assert main([*args, "--out", str(tmp_path / "run"), "--no-progress"]) == 128 + sig
    finally:
        signal.signal(sig, saved)
    err = capfd.readouterr().err
    assert "Received SIGTERM" not in err and err.endswith("crowdmpc train: interrupted\n"), err
    assert "KeyboardInterrupt" not in err and "\n\n" not in err, err


@pytest.mark.parametrize("command", ["zoo", "simulate", "sweep"])
def test_help_examples_name_the_plugin_model_train_writes(command, capsys):
    """`zoo --help` added `runs/train/mynet_eth/mynet_eth.pt` after training `my_predictor:MyNet`, whose run
    writes `runs/train/my_net_eth/my_net_eth.pt` (train's default name splits the class name's words): the
    example stopped on "is not a file". Every help example naming that model must use train's name."""
    from pipelines.commands.train import default_name

    name = default_name("my_predictor:MyNet", None, "biwi_eth", explicit_files=False)
    with pytest.raises(SystemExit):
        main([command, "--help"])
    lines = capsys.readouterr().out.replace("\\\n", " ").splitlines()  # an example's continued lines as one
    examples = [line for line in lines if "my_predictor:MyNet" in line]
    assert examples, f"{command} --help has no example with the plugin"
    text = " ".join(examples)
    named = set(re.findall(r"\b(my_?net\w*_eth)\b", text))
    assert named <= {name}, f"{command} --help names {sorted(named)}; train writes {name!r}"
    if command == "zoo":
        assert f"runs/train/{name}/{name}.pt" in text


def test_evaluate_json_is_strict_with_a_figure_that_is_not_finite(tmp_path, monkeypatch):
    """evaluate --json was written with json.dumps as it stood: a non-finite figure (a predictor's inf) came
    out as a bare Infinity, which strict readers (jq, JavaScript, Go) refuse. It is null, as in every
    record."""
    import predictors.evaluate

    summarize = predictors.evaluate.summarize
    monkeypatch.setattr(predictors.evaluate, "summarize", lambda scores: summarize(scores) | {"ade": np.inf})
    walk, out = write_walk_file(tmp_path / "walk.ndjson"), tmp_path / "scores.json"
    assert (
        main(["evaluate", "--predictor", "constant_velocity", "--test", str(walk), "--json", str(out)]) == 0
    )
    refuse = lambda token: pytest.fail(f"not strict JSON: {token}")  # noqa: E731
    scores = json.loads(out.read_text(), parse_constant=refuse)
    assert scores["overall"]["ade"] is None and scores["overall"]["fde"] == 0.0  # a straight walk


def test_zoo_add_refuses_metrics_beside_an_edited_config(trained, capsys):
    """zoo add checked the weights against the metrics, not the config: NAME.json edited to another input
    scale (the same tensors) was added with the trained model's test ADE, its own off by a factor of five."""
    out, _ = trained
    config = out / "walker.json"
    document = json.loads(config.read_text())
    document["net"]["input_scale"] = 2 * document["net"].get("input_scale", 1.0)
    before = config.read_text()
    config.write_text(json.dumps(document, indent=2) + "\n")
    capsys.readouterr()
    assert main(["zoo", "add", str(out / "walker.pt")]) == 2
    err = capsys.readouterr().err
    assert f"error: {config} is not the config {out / 'walker.metrics.json'} was measured with" in err
    config.write_text(before)  # as train wrote it: added
    assert main(["zoo", "add", str(out / "walker.pt")]) == 0


@pytest.mark.parametrize("label, refused", [("paper", True), ("loo", True), ("synth", False)])
def test_zoo_add_protocol_cannot_call_a_run_of_ones_own_files_trajnets(trained, capsys, label, refused):
    out, _ = trained  # a run of its own --train/--val files: protocol custom
    assert main(["zoo", "add", str(out / "walker.pt"), "--protocol", label]) == (2 if refused else 0)
    if refused:
        assert "records a run of protocol 'custom'" in capsys.readouterr().err


def test_zoo_add_of_a_lightning_checkpoint_names_what_to_add(trained, capsys):
    out, _ = trained
    last = out / "checkpoints" / "last.ckpt"
    assert main(["zoo", "add", str(last)]) == 2
    assert f"{last} is a Lightning training checkpoint, not a zoo one" in capsys.readouterr().err


def test_evaluate_notes_a_file_the_model_was_trained_on(trained, tmp_path, capsys):
    out, args = trained
    assert main(["zoo", "add", str(out / "walker.pt")]) == 0
    from tests.predictors.samples import write_crowds

    data = args[args.index("--train") + 1]  # its --train, --val and --test file
    capsys.readouterr()
    assert main(["evaluate", "--predictor", "walker", "--test", data, "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert f"note: {data} holds the data walker was trained on (train file " in err
    assert "these scores are not on held-out data" in err
    other = write_crowds(tmp_path / "crowds.ndjson")  # data it never saw: no note
    assert main(["evaluate", "--predictor", "walker", "--test", str(other), "--no-progress"]) == 0
    assert "note:" not in capsys.readouterr().err


def test_the_default_name_says_a_pooling_other_than_the_kinds_own():
    """`train --model social_gru --pooling none` trained a plain GRU named social_gru_eth, the name of the
    shipped pooled one; social_lstm_soft and social_gan_grid were named so already."""
    from pipelines.commands.train import default_name

    names = {
        (kind, pooling): default_name(kind, pooling, "biwi_eth", explicit_files=False)
        for kind, pooling in [
            ("social_gru", "none"),
            ("social_gru", "grid"),
            ("social_gru", "soft"),
            ("social_lstm", "soft"),
            ("social_lstm", "grid"),
            ("social_gan", "grid"),
            ("vanilla_lstm", "none"),
            ("social_attention", None),
        ]  # fmt: skip
    }
    assert names == {
        ("social_gru", "none"): "social_gru_none_eth",
        ("social_gru", "grid"): "social_gru_grid_eth",
        ("social_gru", "soft"): "social_gru_eth",
        ("social_lstm", "soft"): "social_lstm_soft_eth",
        ("social_lstm", "grid"): "social_lstm_eth",
        ("social_gan", "grid"): "social_gan_grid_eth",
        ("vanilla_lstm", "none"): "vanilla_lstm_eth",
        ("social_attention", None): "social_attention_eth",
    }


# a train whose third checkpoint save (epoch 1's best, after epoch 0's best and last) is killed (kill -9: no
# finally runs) after the checkpoint was written and before it took its name
_KILLED_CHECKPOINT_SAVE = """
import os, shutil, sys
from pipelines.cli import main
saves, replace, move = [], os.replace, shutil.move
def named(src, dst, *args, **kwargs):
    if str(dst).endswith(".ckpt"):
        saves.append(dst)
        if len(saves) == 3:
            os._exit(137)
    return (move if named.move else replace)(src, dst, *args, **kwargs)
def moved(src, dst, *args, **kwargs):
    named.move = True
    try:
        return named(src, dst, *args, **kwargs)
    finally:
        named.move = False
named.move = False
os.replace, shutil.move = named, moved
sys.exit(main(sys.argv[1:]))
"""


def test_a_checkpoint_save_stopped_by_a_kill_leaves_no_copy_past_the_next_run(tmp_path):
    """Lightning wrote each checkpoint to a temporary of the temp directory (tempfile.mkstemp), then moved it
    into --out: a kill -9 in between left a copy of the weights and the optimiser's state in $TMPDIR that no
    later run removed (80 MB a kill for a net of hidden size 1024), and where $TMPDIR is another file system
    the move was a copy, which a kill left half written under the checkpoint's own name. A checkpoint is now
    written beside its name and renamed, and the next run into --out removes what a killed save left."""
    import os
    import subprocess
    import sys
    import time

    data = str(write_walk_file(tmp_path / "walk.ndjson"))
    out, tmp = tmp_path / "run", tmp_path / "tmp"
    tmp.mkdir()
    args = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--epochs", "2"]
    args += ["--out", str(out), "--name", "walker", "--no-progress"]
    killed = subprocess.run(
        [sys.executable, "-c", _KILLED_CHECKPOINT_SAVE, *args],
        cwd=Path(__file__).resolve().parents[2],
        env=os.environ | {"TMPDIR": str(tmp)},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert killed.returncode == 137, killed.stderr[-2000:]
    assert [p.name for p in tmp.iterdir() if p.is_file()] == []  # (torch's torchinductor_root folder aside)
    left = [p for p in (out / "checkpoints").iterdir() if not p.name.endswith(".ckpt")]
    assert left  # the killed save's, beside the checkpoint it was to become
    # and one of a best checkpoint whose val_ade the resumed run will not reach again
    left.append(out / "checkpoints" / ".best-epoch=007-val_ade=9.8765.ckpt.k1ll3d_0.part")
    left[-1].write_bytes(b"a killed save's checkpoint")
    old = time.time() - 3600  # a killed writer's: unlocked, and older than a live one's could be
    for path in left:
        os.utime(path, (old, old))
    assert main([*args, "--resume"]) == 0
    assert [p.name for p in (out / "checkpoints").iterdir() if not p.name.endswith(".ckpt")] == []
    assert (out / "walker.metrics.json").is_file()


def test_a_resume_refuses_a_key_its_settings_file_never_held(trained, capsys):
    """A misspelt key ("seed" edited to "sed") was ignored: the resume took the default seed in its place and
    refused the run as "seed: checkpoint ..., now 0", naming neither the file nor the key. It is refused by
    name now; the file as train wrote it holds only keys a run's file may hold."""
    from pipelines.commands.train_resume import SETTINGS_KEYS

    out, args = trained
    path = out / "train_settings.json"
    settings = json.loads(path.read_text())
    assert set(settings) <= set(SETTINGS_KEYS)
    settings["sed"] = settings.pop("seed")
    path.write_text(json.dumps(settings))
    assert main([*[a if a != "1" else "2" for a in args], "--resume"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path} holds the key 'sed', which crowdmpc train never writes" in err
    assert "the file holds only name, model, " in err and "seed: checkpoint" not in err


@pytest.mark.parametrize(
    ("key", "shown"),
    [("s\u0435ed", "'s\\u0435ed'"), ("x" * 1_000_000, "'" + "x" * 56 + "...")],
    ids=["look-alike", "long"],
)
def test_a_settings_key_is_named_as_it_is_spelt_and_short(tmp_path, key, shown):
    """A key spelt with a Cyrillic 'е' was named 'sеed', the very name the line listed as one the file may
    hold, and a key of a million characters made the one-line refusal a megabyte long."""
    from pipelines.commands.train_resume import read_run_settings

    (tmp_path / "train_settings.json").write_text(json.dumps({"seed": 0, key: 1}))
    with pytest.raises(PipelineError) as refused:
        read_run_settings(tmp_path)
    assert f"holds the key {shown}, which crowdmpc train never writes" in str(refused.value)
    assert len(str(refused.value)) < 1000
