"""What the zoo never lets a command destroy: its own files (manifest, calibrations, lock) under a model's
name, a shipped model replaced without --replace, entries of parallel adds and removes, zoo files overwritten
by `crowdmpc export`, and a manifest of a newer layout read as if it were this one's.

Every zoo here lives in tmp_path (checkpoints/ is only read); the parallel cases run real processes.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import casadi
import numpy as np
import pytest

from pipelines.cli import main
from predictors import manifest, zoo, zoo_edit, zoo_remove
from predictors.calibration_store import CALIBRATIONS_NAME
from predictors.errors import PredictorError
from tests.predictors.test_zoo import retrained  # its metrics are the pair's: here an empty file
from tests.read_only import file_size_limit

REPO = Path(__file__).resolve().parents[2]
REAL_ZOO = REPO / "checkpoints"
NAME = "social_lstm_eth"


# ------------------------------------------------------------------------------------------------ fixtures
def snapshot(root: Path) -> dict[str, str]:
    """Every file under ``root`` and its sha256: what "untouched" means."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in root.rglob("*")
        if p.is_file()
    }


def copy_pair(directory: Path, stem: str = NAME) -> Path:
    """A copy of the real checkpoint pair ``directory/stem.pt``/``.json`` with an empty metrics file."""
    directory.mkdir(parents=True, exist_ok=True)
    for suffix in (".pt", ".json"):
        shutil.copyfile(REAL_ZOO / f"{NAME}{suffix}", directory / f"{stem}{suffix}")
    (directory / f"{stem}.metrics.json").write_text("{}")
    return directory / f"{stem}.pt"


@pytest.fixture
def shipped(tmp_path, monkeypatch) -> Path:
    """A clone's shipped zoo (--shipped needs the pyproject.toml beside it) holding the real entry NAME
    and a calibrations file."""
    root = tmp_path / "checkpoints"
    copy_pair(root).with_suffix(".metrics.json").unlink()
    document = json.loads((REAL_ZOO / manifest.MANIFEST_NAME).read_text())
    document["models"] = [e for e in document["models"] if e["name"] == NAME]
    (root / manifest.MANIFEST_NAME).write_text(json.dumps(document))
    (root / CALIBRATIONS_NAME).write_text(
        '{"format": "crowdmpc-calibrations", "version": 1, "calibrations": []}'
    )
    (tmp_path / "pyproject.toml").write_text("")
    monkeypatch.setenv(zoo.CHECKPOINTS_ENV, str(root))
    return root


@pytest.fixture
def user(tmp_path, monkeypatch) -> Path:
    """A user zoo with one model ("mine") and the calibrations `crowdmpc calibrate` keeps there."""
    root = tmp_path / "user"
    monkeypatch.setenv(zoo.ZOO_ENV, str(root))
    zoo_edit.add_to_zoo(copy_pair(tmp_path / "run"), name="mine", protocol="p", training_data={}, metrics={})
    (root / CALIBRATIONS_NAME).write_text(
        '{"format": "crowdmpc-calibrations", "version": 1, "calibrations": []}'
    )
    return root


@pytest.fixture
def pair(tmp_path) -> Path:
    return copy_pair(tmp_path / "src")


def cli(args: list[str], capsys) -> tuple[int, str, str]:
    """Exit code, stdout, and stderr's one line (asserted to be at most one)."""
    capsys.readouterr()
    code = main(args)
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) <= 1, lines
    return code, captured.out, lines[0] if lines else ""


# ------------------------------------------------------------------------------ the zoo's own files' names
@pytest.mark.parametrize(
    ("name", "own", "what"),
    [
        ("calibrations", CALIBRATIONS_NAME, "conformal calibrations (kept by `crowdmpc calibrate`)"),
        ("manifest", manifest.MANIFEST_NAME, "manifest (the list of its models)"),
        ("Calibrations", CALIBRATIONS_NAME, "conformal calibrations (kept by `crowdmpc calibrate`)"),
        ("MANIFEST", manifest.MANIFEST_NAME, "manifest (the list of its models)"),
    ],
)
@pytest.mark.parametrize("where", ["user", "shipped"])
def test_a_name_whose_files_are_the_zoos_own_is_refused(shipped, user, pair, capsys, name, own, what, where):
    root = shipped if where == "shipped" else user
    before = snapshot(root)
    code, _, err = cli(
        ["zoo", "add", str(pair), "--name", name, *(["--shipped"] * (where == "shipped"))], capsys
    )
    assert (code, err) == (
        2,
        f"crowdmpc zoo add: error: zoo name {name!r} is reserved: its file {name}.json would "
        f"overwrite {own}, "
        f"the zoo's {what} (names are compared ignoring case); pick another name",
    )
    assert snapshot(root) == before
    with pytest.raises(PredictorError, match="is reserved"):  # --replace does not make it free
        zoo_edit.add_to_zoo(pair, name=name, protocol="p", training_data={}, metrics={}, replace=True)
    assert snapshot(root) == before


def test_names_that_only_contain_a_reserved_one_are_fine(user, pair, capsys):
    for name in ("manifest_lstm", "calibrations.v2", "my-manifest"):
        assert cli(["zoo", "add", str(pair), "--name", name], capsys)[0] == 0
    assert zoo.zoo_names(user) == ["calibrations.v2", "manifest_lstm", "mine", "my-manifest"]
    assert all(problem is None for _, problem in zoo.verify(user))


def test_removing_an_old_entry_under_a_reserved_name_keeps_the_zoos_files(user, capsys):
    """An older crowdmpc added "calibrations" over calibrations.json: removing it must not delete the
    calibrations kept there since."""
    entries = json.loads((user / manifest.MANIFEST_NAME).read_text())
    old = {
        **entries["models"][0],
        "name": "calibrations",
        "file": "calibrations.pt",
        "config": CALIBRATIONS_NAME,
    }
    entries["models"].append(old)
    (user / manifest.MANIFEST_NAME).write_text(json.dumps(entries))
    shutil.copyfile(user / "mine.pt", user / "calibrations.pt")
    calibrations = (user / CALIBRATIONS_NAME).read_bytes()
    code, out, _ = cli(["zoo", "remove", "calibrations"], capsys)
    assert code == 0 and out == f"removed calibrations from the user zoo {user}\n"
    assert (user / CALIBRATIONS_NAME).read_bytes() == calibrations and not (user / "calibrations.pt").exists()
    assert zoo.zoo_names(user) == ["mine"]


# --------------------------------------------------------------------------------- the shipped zoo's names
def test_a_shipped_model_is_replaced_only_with_replace(shipped, pair, capsys):
    first = zoo.read_manifest(shipped)[NAME]
    before = snapshot(shipped)
    other = retrained(pair, "other")
    code, _, err = cli(["zoo", "add", str(other), "--shipped", "--name", NAME], capsys)
    assert (code, err) == (
        2,
        f"crowdmpc zoo add: error: the shipped zoo {shipped} already has {NAME!r}: sha256 "
        f"{first.sha256[:12]}…, "
        "model social_lstm; add it with --replace to replace that entry, or under another --name",
    )
    assert snapshot(shipped) == before

    code, out, _ = cli(["zoo", "add", str(other), "--shipped", "--name", NAME, "--replace"], capsys)
    new = zoo.read_manifest(shipped)[NAME]
    assert code == 0 and out.startswith(
        f"replaced {NAME} (was sha256 {first.sha256[:12]}…, model social_lstm)"
    )
    assert out.rstrip().endswith(f"in the shipped zoo {shipped}")
    assert new.sha256 == hashlib.sha256(other.read_bytes()).hexdigest() != first.sha256


# ------------------------------------------------------------------------------------ interrupted replaces
class Interrupted(BaseException):
    """A Ctrl-C or a kill at that instant (BaseException, as KeyboardInterrupt: no handler catches it)."""


def half_copy(source, destination, *_args, **_kwargs):
    """shutil.copyfile / copyfileobj that writes half the file, then is interrupted."""
    if isinstance(source, (str, Path)):
        data = Path(source).read_bytes()
        Path(destination).write_bytes(data[: len(data) // 2])
    else:
        data = source.read()
        destination.write(data[: len(data) // 2])
        destination.flush()
    raise Interrupted


def half_write(target: Path, data: bytes) -> None:
    """zoo_edit._write_synced (the weights' bytes as they loaded, then the config's) that writes half of
    ``data``, then is interrupted."""
    Path(target).write_bytes(data[: len(data) // 2])
    raise Interrupted


def entry_state(root: Path, name: str) -> tuple[str | None, str]:
    """The zoo's verdict on ``name`` (None: loads, hashes as recorded) and the sha256 its entry records."""
    problems = dict(zoo.verify(root))
    return problems[name], zoo.read_manifest(root)[name].sha256


def test_a_replace_interrupted_while_copying_keeps_the_old_entry(tmp_path, user, monkeypatch):
    old = zoo.read_manifest(user)["mine"]
    new = retrained(copy_pair(tmp_path / "run2"), "mine2")
    with monkeypatch.context() as patched, pytest.raises(Interrupted):
        patched.setattr(shutil, "copyfile", half_copy)
        patched.setattr(shutil, "copyfileobj", half_copy)
        patched.setattr(zoo_edit, "_write_synced", half_write)
        zoo_edit.add_to_zoo(new, name="mine", protocol="p", training_data={}, metrics={}, replace=True)
    assert entry_state(user, "mine") == (None, old.sha256)
    assert hashlib.sha256((user / "mine.pt").read_bytes()).hexdigest() == old.sha256
    # the same command again finishes the replace, and leaves no temporary file
    zoo_edit.add_to_zoo(new, name="mine", protocol="p", training_data={}, metrics={}, replace=True)
    assert entry_state(user, "mine") == (None, hashlib.sha256(new.read_bytes()).hexdigest())
    assert not [p.name for p in user.iterdir() if p.name.startswith(".mine")]


@pytest.mark.parametrize("call", [1, 2, 3])
def test_a_replace_interrupted_at_any_later_step_leaves_a_consistent_entry(tmp_path, user, monkeypatch, call):
    """Interrupted at the manifest's first write, a rename into place, or its last write: the entry loads
    and is the old model or the new one."""
    old = zoo.read_manifest(user)["mine"]
    new = retrained(copy_pair(tmp_path / "run2"), "mine2")
    new_sha = hashlib.sha256(new.read_bytes()).hexdigest()
    calls = []
    real_replace = os.replace

    def replace(source, target, *args, **kwargs):
        calls.append(target)  # every rename: the manifest's, and each file's into place
        if len(calls) == call:
            raise Interrupted
        return real_replace(source, target, *args, **kwargs)

    with monkeypatch.context() as patched, pytest.raises(Interrupted):
        patched.setattr(os, "replace", replace)
        zoo_edit.add_to_zoo(new, name="mine", protocol="p", training_data={}, metrics={}, replace=True)
    problem, recorded = entry_state(user, "mine")
    assert problem is None and recorded in (old.sha256, new_sha)
    # the same command again finishes the replace: mine.pt and mine.json are the stopped add's, no stray files
    zoo_edit.add_to_zoo(new, name="mine", protocol="p", training_data={}, metrics={}, replace=True)
    assert entry_state(user, "mine") == (None, new_sha)
    assert not [p.name for p in user.iterdir() if p.name.startswith(".mine")]


def test_a_remove_interrupted_after_its_manifest_write_is_finished_by_remove(user, monkeypatch, capsys):
    """The manifest without "mine", its 34 MB of files still there: `zoo remove mine` said "has no entry"
    and left them for good."""

    def interrupted(*_args, **_kwargs):
        raise Interrupted

    with monkeypatch.context() as patched, pytest.raises(Interrupted):
        patched.setattr(Path, "unlink", interrupted)  # after the manifest's rename, before the files go
        zoo_remove.remove_from_zoo("mine", user)
    assert "mine" not in zoo.read_manifest(user) and not (user / "mine.pt").exists()
    (user / ".mine.pt.123.new").write_bytes(b"an add's temporary copy")
    code, out, _ = cli(["zoo", "remove", "mine"], capsys)
    pid = os.getpid()
    # listed in name order, which depends on this process's pid (1199 sorts before 123)
    names = sorted([f".mine.json.{pid}.removed", ".mine.pt.123.new", f".mine.pt.{pid}.removed"])
    listed = f"removed its leftover files {', '.join(names)}"
    assert code == 0 and listed in out
    own = [CALIBRATIONS_NAME, manifest.MANIFEST_NAME, manifest.LOCK_NAME]
    assert sorted(p.name for p in user.iterdir()) == sorted(own)
    code, _, line = cli(["zoo", "remove", "mine"], capsys)
    assert code == 2 and "has no entry 'mine'" in line


def test_a_remove_whose_manifest_the_disk_refuses_leaves_the_entry_whole(user, capsys):
    """`zoo remove mine` on a full disk (here `ulimit -f`, below the manifest's size) renamed the model's
    files away, then failed to write the manifest: "mine" was still listed, its files gone (every command
    using it said "checkpoint file .../mine.pt does not exist"), and two hidden copies left. The files go
    back now: the zoo as it was, and one line."""
    before = snapshot(user)
    with file_size_limit(16):  # the manifest without "mine" is longer
        code, _, line = cli(["zoo", "remove", "mine"], capsys)
    assert (
        code == 2
        and line.startswith("crowdmpc zoo remove: error: could not write")
        and "(File too large)" in line
    )
    assert snapshot(user) == before and zoo.verify(user)[-1] == ("mine", None)


def test_a_manifest_the_disk_refuses_is_named(user, capsys):
    """A write's OSError names no file: the full disk's line said "could not write (File too large)" of a
    zoo add or remove, leaving the user to guess which file; it names the zoo's manifest now."""
    with file_size_limit(16):
        code, _, line = cli(["zoo", "remove", "mine"], capsys)
    assert code == 2 and f"could not write {user / manifest.MANIFEST_NAME} (File too large)" in line


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="names a descriptor's file through /proc")
def test_the_manifest_and_calibrations_reach_the_disk_before_they_replace_the_old(tmp_path, monkeypatch):
    """Written and renamed unsynced, a power loss could leave the rename on disk without its data: an empty
    manifest, the user zoo's every model lost (as the calibrations). Each is synced before its rename, and
    its directory after."""
    from predictors.calibration_store import save_calibration
    from tests.calibration_blocks import class_errors, constant_velocity_block

    synced: list[str] = []
    fsync = os.fsync

    def recorded(fd: int) -> None:
        synced.append(os.readlink(f"/proc/self/fd/{fd}"))
        fsync(fd)

    monkeypatch.setattr(os, "fsync", recorded)
    manifest.write_manifest({}, tmp_path)
    save_calibration(constant_velocity_block(class_errors(4)[0]), tmp_path)
    temporaries = [
        str(tmp_path / f".{name}.{os.getpid()}.tmp") for name in (manifest.MANIFEST_NAME, CALIBRATIONS_NAME)
    ]
    assert synced == [temporaries[0], str(tmp_path), temporaries[1], str(tmp_path)]
    assert zoo.read_manifest(tmp_path) == {} and (tmp_path / CALIBRATIONS_NAME).is_file()


def test_verify_names_the_leftovers_of_a_stopped_remove(user, monkeypatch, capsys):
    """`zoo verify` listed the entries only: the hidden copies a stopped remove left (as large as the model)
    were named by no line, and a user learnt of them only by a second `zoo remove mine`."""
    code, out, _ = cli(["zoo", "verify"], capsys)
    assert code == 0 and "left by" not in out

    def interrupted(*_args, **_kwargs):
        raise Interrupted

    with monkeypatch.context() as patched, pytest.raises(Interrupted):
        patched.setattr(Path, "unlink", interrupted)
        zoo_remove.remove_from_zoo("mine", user)
    (user / ".other.json.77.link").write_text("{}")
    (user / ".not_ours.pt.new").write_text("no pid: nobody's temporary")
    code, out, _ = cli(["zoo", "verify"], capsys)
    pid = os.getpid()
    named = [line.split(":")[0] for line in out.splitlines() if "left by" in line]
    hidden = [f".mine.json.{pid}.removed", f".mine.pt.{pid}.removed", ".other.json.77.link"]
    assert code == 0 and named == [str(user / name) for name in sorted(hidden)]
    assert "`crowdmpc zoo remove --leftovers mine` removes it" in out and "remove --leftovers other`" in out
    code, out, _ = cli(["zoo", "--dir", str(user), "verify"], capsys)
    assert f"`crowdmpc zoo --dir {user} remove --leftovers mine` removes it" in out
    assert cli(["zoo", "remove", "--leftovers", "mine"], capsys)[0] == 0
    assert "remove --leftovers mine" not in cli(["zoo", "verify"], capsys)[1]


def test_the_leftovers_of_a_model_with_an_entry_go_and_the_model_stays(user, capsys):
    """verify advised `zoo remove mine` for a stale copy beside a live entry "mine": following it deleted the
    model and left the copy (a second remove took that)."""
    (user / ".mine.pt.123.new").write_bytes(b"a killed add's copy")
    code, out, _ = cli(["zoo", "verify"], capsys)
    assert code == 0 and "`crowdmpc zoo remove --leftovers mine` removes it" in out
    code, out, _ = cli(["zoo", "remove", "--leftovers", "mine"], capsys)
    assert code == 0 and out.strip().endswith(": .mine.pt.123.new")
    assert "mine" in zoo.read_manifest(user) and (user / "mine.pt").is_file()
    assert not (user / ".mine.pt.123.new").exists()
    (user / ".mine.pt.124.new").write_bytes(b"another")
    assert cli(["zoo", "remove", "mine"], capsys)[0] == 0  # the model, and what its adds left
    assert not (user / ".mine.pt.124.new").exists() and "mine" not in zoo.read_manifest(user)


def test_remove_never_takes_a_model_no_entry_names(user, tmp_path, capsys):
    """`zoo --dir RUN remove NAME` on a training run's folder (no manifest entry names its NAME.pt) deleted
    the trained weights as "leftovers"; it is refused as before, and the files stay."""
    run = tmp_path / "a_training_run"
    run.mkdir()
    (run / "mine.pt").write_bytes(b"trained weights")
    (run / "mine.json").write_text("{}")
    code, _, line = cli(["zoo", "--dir", str(run), "remove", "mine"], capsys)
    assert code == 2 and "has no entry 'mine'" in line
    assert (run / "mine.pt").read_bytes() == b"trained weights" and (run / "mine.json").is_file()


@pytest.mark.parametrize("suffix", [".pt", ".json"])
@pytest.mark.parametrize("target", ["kept", "other"])
def test_remove_takes_a_symbolic_link_never_the_file_it_points_to(user, pair, capsys, suffix, target):
    """mine.pt a link to another file of the zoo: remove deleted that file (the user's own "kept", or
    entry "other"'s was kept and the link with it) and a later `zoo add --name mine` was refused."""
    if target == "other":
        zoo_edit.add_to_zoo(pair, name="other", protocol="p", training_data={}, metrics={})
    else:
        os.replace(user / f"mine{suffix}", user / f"kept{suffix}")
    (user / f"mine{suffix}").unlink(missing_ok=True)
    (user / f"mine{suffix}").symlink_to(f"{target}{suffix}")
    before = (user / f"{target}{suffix}").read_bytes()
    if target == "kept":  # other.json names "other", so mine's recorded sha256 is not its
        assert cli(["zoo", "verify"], capsys)[0] == 0  # the entry loads through the link
    assert cli(["zoo", "remove", "mine"], capsys)[0] == 0
    assert not os.path.lexists(user / f"mine{suffix}") and not os.path.lexists(user / "mine.pt")
    assert (user / f"{target}{suffix}").read_bytes() == before
    code, _, err = cli(["zoo", "add", str(pair), "--name", "mine"], capsys)
    assert (code, err) == (0, "") and "mine" in zoo.read_manifest(user)
    assert not (user / f"mine{suffix}").is_symlink()


@pytest.mark.parametrize("suffix", [".pt", ".json"])
@pytest.mark.parametrize("replace", [[], ["--replace"]])
def test_add_never_replaces_a_file_no_entry_of_that_name_owns(user, pair, capsys, suffix, replace):
    """A file of the user's named like the new entry's weights or config (theirs.pt, theirs.json) was
    replaced without a word; the add is refused, --replace or not (there is no entry to replace)."""
    (user / f"theirs{suffix}").write_bytes(b"the user's own file")
    before = snapshot(user)
    code, _, err = cli(["zoo", "add", str(pair), "--name", "theirs", *replace], capsys)
    assert (code, err) == (
        2,
        f"crowdmpc zoo add: error: {user / f'theirs{suffix}'} is in the user zoo but the zoo has no entry "
        "'theirs'; adding would replace it: move that file away, or add under another --name",
    )
    assert snapshot(user) == before and zoo.zoo_names(user) == ["mine"]


def test_add_into_a_training_runs_folder_keeps_its_weights(tmp_path, pair, capsys):
    """`zoo --dir RUN add` under the name of the run's own NAME.pt, which no manifest names."""
    run = tmp_path / "a_training_run"
    run.mkdir()
    (run / "mine.pt").write_bytes(b"trained weights")
    code, _, err = cli(["zoo", "--dir", str(run), "add", str(pair), "--name", "mine"], capsys)
    assert code == 2 and err.startswith(f"crowdmpc zoo add: error: {run / 'mine.pt'} is in the user zoo but")
    assert sorted(p.name for p in run.iterdir()) == ["mine.pt"]
    assert (run / "mine.pt").read_bytes() == b"trained weights"


def test_a_training_runs_folder_given_as_the_zoo_takes_the_run_itself(tmp_path, capsys):
    """`zoo --dir RUN add RUN/NAME.pt`: the files in place are the ones added, not another's to keep."""
    weights = copy_pair(tmp_path / "run", "trained")
    before = weights.read_bytes()
    code, out, err = cli(["zoo", "--dir", str(weights.parent), "add", str(weights)], capsys)
    assert code == 0 and not err and zoo.zoo_names(weights.parent) == ["trained"]
    assert weights.read_bytes() == before and zoo.verify(weights.parent)[-1] == ("trained", None)


def test_removing_the_entry_of_a_stopped_add_takes_the_files_it_was_putting_in_place(
    tmp_path, user, monkeypatch, capsys
):
    """An add of a new name stopped between its manifest's writes (the entry naming its staged copies,
    fresh.pt already in place): `zoo remove fresh` left fresh.pt, no entry's, and the add of fresh again was
    refused as a stray file's."""
    real_replace, calls = os.replace, []

    def replace(source, target, *args, **kwargs):
        calls.append(target)  # the manifest's write, fresh.pt's rename into place, fresh.json's
        if len(calls) == 3:
            raise Interrupted
        return real_replace(source, target, *args, **kwargs)

    new = copy_pair(tmp_path / "run2", "fresh")
    with monkeypatch.context() as patched, pytest.raises(Interrupted):
        patched.setattr(os, "replace", replace)
        zoo_edit.add_to_zoo(new, name="fresh", protocol="p", training_data={}, metrics={})
    assert (user / "fresh.pt").exists() and zoo.read_manifest(user)["fresh"].file.startswith(".fresh.pt.")
    assert cli(["zoo", "remove", "fresh"], capsys)[0] == 0
    assert not [p.name for p in user.iterdir() if "fresh" in p.name]
    assert cli(["zoo", "add", str(new)], capsys)[0] == 0 and zoo.verify(user)[0] == ("fresh", None)


@pytest.mark.parametrize("call", [2, 3])
def test_an_add_stopped_between_its_manifests_writes_is_finished_by_the_same_command(
    tmp_path, user, monkeypatch, capsys, call
):
    """The entry naming the add's staged copies: the same `zoo add` again was refused as a name the zoo has
    ("the same weights, with other metrics or settings; add it with --replace"), and --replace left the
    staged copies behind."""
    real_replace, calls = os.replace, []

    def replace(source, target, *args, **kwargs):
        calls.append(target)
        if len(calls) == call:
            raise Interrupted
        return real_replace(source, target, *args, **kwargs)

    new = copy_pair(tmp_path / "run2", "fresh")
    with monkeypatch.context() as patched, pytest.raises(Interrupted):
        patched.setattr(os, "replace", replace)
        main(["zoo", "add", str(new)])
    code, out, err = cli(["zoo", "add", str(new)], capsys)
    assert code == 0 and not err, err
    assert zoo.verify(user)[0] == ("fresh", None) and zoo.read_manifest(user)["fresh"].file == "fresh.pt"
    assert not [p.name for p in user.iterdir() if p.name.startswith(".fresh")]
    assert out.startswith("added fresh")  # finished, not "replaced": no model was there before


# ---------------------------------------------------------------------------------- parallel adds, removes
CHILD = """
import sys, time
from pathlib import Path
from pipelines.cli import main
import predictors.zoo_edit, predictors.learned, torch  # loaded before the start, so that the commands overlap
ready, go = Path(sys.argv[1]), Path(sys.argv[2])
ready.touch()
while not go.exists():
    time.sleep(0.001)
sys.exit(main(sys.argv[3:]))
"""


def run_together(commands: list[list[str]], sync: Path) -> list[subprocess.CompletedProcess]:
    """Run ``crowdmpc`` ``commands`` as processes that each wait, everything imported, for one start signal,
    so that their reads and writes of the manifest overlap."""
    sync.mkdir()
    go = sync / "go"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    processes = [
        subprocess.Popen(
            [sys.executable, "-c", CHILD, str(sync / f"ready{i}"), str(go), *command],
            cwd=REPO,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i, command in enumerate(commands)
    ]
    deadline = time.monotonic() + 120
    while len(list(sync.glob("ready*"))) < len(commands) and time.monotonic() < deadline:
        time.sleep(0.01)
    go.touch()
    results = []
    for process, command in zip(processes, commands, strict=True):
        out, err = process.communicate(timeout=120)
        results.append(subprocess.CompletedProcess(command, process.returncode, out, err))
    return results


def test_parallel_adds_and_removes_all_count(tmp_path, shipped, user, pair):
    adds = [["zoo", "add", str(pair), "--name", f"race{i}"] for i in range(4)]
    results = run_together([*adds, ["zoo", "remove", "mine"]], tmp_path / "sync")
    for result in results:
        assert result.returncode == 0, result
    assert [r.stdout.split()[0] for r in results] == ["added"] * 4 + ["removed"]

    names = [f"race{i}" for i in range(4)]
    assert zoo.zoo_names(user) == names
    assert all(problem is None for _, problem in zoo.verify(user))
    own = {manifest.MANIFEST_NAME, CALIBRATIONS_NAME, manifest.LOCK_NAME}
    assert set(snapshot(user)) == own | {f"{n}{s}" for n in names for s in (".pt", ".json")}  # no orphans


def test_a_lock_planted_as_a_symbolic_link_is_refused(tmp_path, user, pair):
    elsewhere = tmp_path / "elsewhere"
    (user / manifest.LOCK_NAME).unlink()
    (user / manifest.LOCK_NAME).symlink_to(elsewhere)
    with pytest.raises(
        PredictorError, match=rf"{manifest.LOCK_NAME}: cannot lock the zoo \(it is a symbolic"
    ):
        zoo_edit.add_to_zoo(pair, name="other", protocol="p", training_data={}, metrics={})
    assert not elsewhere.exists() and zoo.zoo_names(user) == ["mine"]


def test_a_lock_planted_as_a_fifo_is_refused_instead_of_waiting_forever(user, pair):
    """Opening a FIFO for writing blocks until a reader comes: zoo add hung."""
    (user / manifest.LOCK_NAME).unlink()
    os.mkfifo(user / manifest.LOCK_NAME)
    with pytest.raises(PredictorError, match=rf"{manifest.LOCK_NAME}: cannot lock the zoo"):
        zoo_edit.add_to_zoo(pair, name="other", protocol="p", training_data={}, metrics={})
    assert zoo.zoo_names(user) == ["mine"]


# ------------------------------------------------------------------------------------------ export's --out
@pytest.mark.parametrize(
    ("where", "which"),
    [
        ("user/mine.pt", "user"),
        ("user/sub/new.casadi", "user"),
        ("link/mine.json", "user"),
        ("shipped", "shipped"),
    ],
)
def test_export_never_writes_into_a_zoo(tmp_path, shipped, user, monkeypatch, capsys, where, which):
    import predictors.registry

    def no_load(name):
        raise AssertionError("a predictor was loaded before --out was checked")

    monkeypatch.setattr(predictors.registry, "load_predictor", no_load)
    (tmp_path / "link").symlink_to(user)
    out = shipped / f"{NAME}.pt" if where == "shipped" else tmp_path / where
    root = (shipped if which == "shipped" else user).resolve()
    before = snapshot(tmp_path)
    code, _, err = cli(["export", "constant_velocity", "--out", str(out)], capsys)
    assert (code, err) == (
        2,
        f"crowdmpc export: error: --out {out} lies in the {which} zoo {root}, whose files only `crowdmpc zoo "
        "add` writes; write the export elsewhere",
    )
    assert snapshot(tmp_path) == before and all(problem is None for _, problem in zoo.verify_entries())


@pytest.mark.parametrize(("where", "which"), [("user", "user"), ("link/run", "user"), ("shipped", "shipped")])
def test_training_never_writes_into_a_zoo(tmp_path, shipped, user, capsys, where, which):
    """`train --out checkpoints --name social_lstm_eth` wrote its NAME.pt and NAME.json over the shipped
    entry's (and its checkpoints/, csv/ and settings beside them): `zoo verify` then failed on its sha256.
    Refused before any data is read, nothing written."""
    (tmp_path / "link").symlink_to(user)
    out = shipped if where == "shipped" else tmp_path / where
    root = (shipped if which == "shipped" else user).resolve()
    before = snapshot(tmp_path)
    argv = ["train", "--model", "vanilla_lstm", "--out", str(out), "--name", NAME, "--no-progress"]
    code, _, err = cli(argv, capsys)
    assert (code, err) == (
        2,
        f"crowdmpc train: error: --out {out} lies in the {which} zoo {root}, whose files only `crowdmpc zoo "
        "add` writes; write the training run elsewhere",
    )
    assert snapshot(tmp_path) == before and all(problem is None for _, problem in zoo.verify_entries())


SIMULATE = ["simulate", "--controller", "straight", "--humans", "1", "--robots", "1", "--no-progress"]
SWEEP = (
    "sweep --experiment controllers --controllers straight --humans 1 --episodes-per-cell 2 --backend inline"
)
SWEEP = SWEEP.split()


@pytest.mark.parametrize(
    ("argv", "option", "where"),
    [
        (SIMULATE, "--record", "checkpoints"),
        (SIMULATE, "--plot", "checkpoints/run.png"),
        (SWEEP, "--out", "checkpoints/sweep"),
        (["evaluate", "--predictor", "constant_velocity"], "--json", "checkpoints/eval.json"),
    ],
)
def test_no_command_writes_its_outputs_into_the_shipped_zoo(
    tmp_path, shipped, user, capsys, argv, option, where
):
    """train and export refused a zoo folder, the other outputs did not: `simulate --record checkpoints`
    wrote a recording among the shipped weights (tracked in git, verified by sha256)."""
    out = tmp_path / where
    before = snapshot(tmp_path)
    code, _, err = cli([*argv, option, str(out)], capsys)
    assert (code, err) == (
        2,
        f"crowdmpc {argv[0]}: error: {option} {out} lies in the shipped zoo {shipped.resolve()}, whose files "
        "only `crowdmpc zoo add` writes; write it elsewhere",
    )
    assert snapshot(tmp_path) == before


def test_outputs_beside_the_user_zoos_entries_are_written_but_never_over_them(
    tmp_path, shipped, user, capsys
):
    """The user zoo is the folder a user names with CROWDMPC_ZOO=DIR, where their reports may go (refusing
    every output there refused a calibrate --json beside it); an entry's own files are kept."""
    (tmp_path / "link").symlink_to(user)
    argv = [*SIMULATE, "--json"]
    for what, name in (("config", "mine.json"), ("weights", "mine.pt")):
        before = snapshot(tmp_path)
        code, _, err = cli([*argv, str(tmp_path / "link" / name)], capsys)
        assert (code, err) == (
            2,
            f"crowdmpc simulate: error: --json {tmp_path / 'link' / name}: that is the {what} of the user "
            "zoo's entry 'mine'; name another file",
        )
        assert snapshot(tmp_path) == before
    assert cli([*argv, str(user / "report.json")], capsys)[0] == 0
    assert (user / "report.json").is_file() and all(problem is None for _, problem in zoo.verify_entries())


def test_training_beside_the_shipped_zoo_never_puts_its_checkpoints_into_it(tmp_path, shipped, capsys):
    """`train --out .` at a clone's top wrote Lightning's last.ckpt and best-*.ckpt into OUT/checkpoints/,
    which is the shipped zoo's folder."""
    out = shipped.parent
    before = snapshot(tmp_path)
    code, _, err = cli(["train", "--model", "vanilla_lstm", "--out", str(out), "--no-progress"], capsys)
    assert (code, err) == (
        2,
        f"crowdmpc train: error: --out {out}: its folder {shipped} lies in the shipped zoo "
        f"{shipped.resolve()}, whose files only `crowdmpc zoo add` writes; write the training run elsewhere",
    )
    assert snapshot(tmp_path) == before


def test_export_beside_a_zoo_still_works(tmp_path, shipped, user):
    out = tmp_path / "user_exports" / "cv.casadi"  # a sibling whose name starts like the zoo's
    assert main(["export", "constant_velocity", "--out", str(out), "--horizon", "2"]) == 0
    f = casadi.Function.load(str(out))
    assert (f.name_in(), f.name_out()) == (["context", "robots_future"], ["humans_future"])
    # 7 humans (the default), human i at (i, -2i) m walking (0.5, 1) m/s; 3 robots' plan over 2 steps
    pos = np.array([[i, -2.0 * i] for i in range(7)])
    context = np.concatenate([pos.ravel(), np.tile([0.5, 1.0], 7)])
    got = np.asarray(f(context, np.arange(2 * 3 * 2.0))).reshape(2, 7, 2)
    # position + (h + 1) tau velocity, tau = 0.4 s: human 1 after 2 steps is at (1 + 0.4, -2 + 0.8)
    np.testing.assert_allclose(got[1, 1], [1.4, -1.2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[0, 3], [3.2, -5.6], rtol=0, atol=1e-12)
    expected = pos[None] + np.array([0.4, 0.8])[:, None, None] * np.array([0.5, 1.0])
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)


# ------------------------------------------------------------------------------------- manifest versions
@pytest.mark.parametrize(
    ("version", "tail"),
    [
        (99, "; a newer crowdmpc wrote it: upgrade crowdmpc to read it"),
        (2, "; a newer crowdmpc wrote it: upgrade crowdmpc to read it"),
        (0, ""),
        ("1", ""),
        (True, ""),
    ],
)
def test_a_manifest_of_a_version_this_code_does_not_know_is_refused(user, pair, capsys, version, tail):
    path = user / manifest.MANIFEST_NAME
    path.write_text(json.dumps({**json.loads(path.read_text()), "version": version}))
    before = snapshot(user)
    message = (
        f'error: {path}: zoo manifest "version" {version!r} is not one this crowdmpc reads (version 1){tail}'
    )
    for command in (["list"], ["add", str(pair), "--name", "other"], ["remove", "mine"]):
        assert cli(["zoo", *command], capsys)[::2] == (2, f"crowdmpc zoo {command[0]}: {message}")
    assert snapshot(user) == before


@pytest.mark.parametrize("action", [["list"], ["show", NAME], ["verify"], ["calibrations"]])
def test_a_user_zoo_that_is_a_file_or_a_missing_dir_is_named_not_passed_over(
    tmp_path, monkeypatch, capsys, action
):
    """Each listed the shipped zoo alone, exit 0, as if the user's were empty."""
    file = tmp_path / "zoo.json"
    file.write_text("{}")
    for argv, message in [
        (["--dir", str(file)], f"--dir: the user zoo {file} is a file, not a directory"),
        (["--dir", str(tmp_path / "typo")], f"--dir {tmp_path / 'typo'}: no such user zoo"),
    ]:
        assert main(["zoo", *argv, *action]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1 and "Traceback" not in err
    monkeypatch.setenv("CROWDMPC_ZOO", str(file))
    assert main(["zoo", *action]) == 2
    assert f"$CROWDMPC_ZOO: the user zoo {file} is a file" in capsys.readouterr().err
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "not_yet"))  # before the first add: empty, not an error
    assert main(["zoo", *action]) == 0


class _Payload:
    def __reduce__(self):  # what a hostile pickle runs on loading; weights_only never calls it
        return (Path.touch, (Path(os.environ["CROWDMPC_TEST_PAYLOAD"]),))


def test_a_pickle_with_code_is_refused_in_one_line_and_never_run(
    tmp_path, pair, monkeypatch, capsys, user, recwarn
):
    """A pickle of protocol 4 in the weights' place: refused as weights_only refuses it, its code never run;
    torch's advice on the protocol came as two lines of warning before the one-line refusal."""
    import pickle

    ran = tmp_path / "payload_ran"
    monkeypatch.setenv("CROWDMPC_TEST_PAYLOAD", str(ran))
    with open(pair, "wb") as f:
        pickle.dump({"w": _Payload()}, f, protocol=4)
    code, _, err = cli(["zoo", "add", str(pair), "--name", "mine2"], capsys)  # cli: one line of stderr
    assert code == 2 and "a pickled object, which is never loaded" in err, err
    assert not ran.exists()
    assert not [w for w in recwarn if "pickle protocol" in str(w.message)]  # shown before the line
