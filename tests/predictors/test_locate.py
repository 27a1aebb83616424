import os
import pwd
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest

from predictors.data import locate
from predictors.data.ewap import SPLITS
from predictors.data.locate import prepared_dir, protocol_files, resolve_data_dir
from predictors.data.prepare import prepare_ewap
from predictors.errors import PredictorError
from tests.predictors.samples import write_tiny_ewap, write_walk_file


@pytest.fixture
def raw_root(tmp_path):
    """A raw data directory like the shared one: raw_ewap/ and TrajNet++ training files beside it."""
    root = tmp_path / "data"
    write_tiny_ewap(root)
    vita = root / "trajnetpp_vita" / "train" / "real_data"
    write_walk_file(vita / "crowds_zara01.ndjson")
    write_walk_file(vita / "biwi_hotel.ndjson")
    return root


@pytest.fixture
def prepared(raw_root, tmp_path):
    out = tmp_path / "prepared"
    prepare_ewap(raw_root / "raw_ewap", out, categorize_scenes=False, log=lambda msg: None)
    return out


def test_data_dir_from_argument_or_environment(tmp_path, monkeypatch):
    monkeypatch.delenv("CROWDMPC_DATA", raising=False)
    with pytest.raises(PredictorError, match="pass --data-dir DIR or set CROWDMPC_DATA"):
        resolve_data_dir(None)
    monkeypatch.setenv("CROWDMPC_DATA", str(tmp_path))
    assert resolve_data_dir(None) == tmp_path
    assert resolve_data_dir(tmp_path / ".") == tmp_path / "."
    with pytest.raises(PredictorError, match="does not exist"):
        resolve_data_dir(tmp_path / "absent")


def test_a_data_dir_starting_with_a_tilde_under_an_empty_home(tmp_path, monkeypatch):
    """expanduser made "~/data" /data under `env HOME= crowdmpc`: the password database's home is taken, as
    for no $HOME, and without one the refusal names where the path came from."""
    (tmp_path / "pw" / "data").mkdir(parents=True)
    monkeypatch.setenv("HOME", "")
    monkeypatch.setattr(pwd, "getpwuid", lambda uid: SimpleNamespace(pw_dir=str(tmp_path / "pw")))
    monkeypatch.setenv("CROWDMPC_DATA", "~/data")
    assert resolve_data_dir(None) == resolve_data_dir("~/data") == tmp_path / "pw" / "data"
    monkeypatch.setattr(pwd, "getpwuid", lambda uid: SimpleNamespace(pw_dir=""))
    with pytest.raises(
        PredictorError, match=r"^cannot find .* for \$CROWDMPC_DATA ~/data .*; set \$CROWDMPC_DATA to"
    ):
        resolve_data_dir(None)
    with pytest.raises(PredictorError, match=r"^cannot find .* for --data-dir ~/data .*; set --data-dir to"):
        resolve_data_dir("~/data")


def test_paper_protocol_files(prepared):
    files = protocol_files(prepared, "paper")
    assert [p.relative_to(prepared).as_posix() for p in files["train"]] == [
        "train/biwi_eth.ndjson",
        "train/biwi_hotel.ndjson",
    ]
    assert [p.name for p in files["val"]] == ["biwi_eth.ndjson", "biwi_hotel.ndjson"]
    assert [p.relative_to(prepared).as_posix() for p in files["test"]] == ["test/biwi_eth.ndjson"]
    hotel = protocol_files(prepared, "paper", "biwi_hotel")
    assert [p.relative_to(prepared).as_posix() for p in hotel["test"]] == ["test/biwi_hotel.ndjson"]


def test_loo_protocol_finds_the_trajnet_files_beside_the_raw_data(prepared, raw_root):
    files = protocol_files(prepared, "loo")
    vita = raw_root / "trajnetpp_vita" / "train" / "real_data"
    # the whole-sequence TrajNet++ hotel file is left out: hotel comes from our own splits
    assert files["train"] == [vita / "crowds_zara01.ndjson", prepared / "train" / "biwi_hotel.ndjson"]
    assert files["val"] == [prepared / "val" / "biwi_hotel.ndjson"]
    assert files["test"] == [prepared / "test" / "biwi_eth.ndjson"]


def test_loo_without_trajnet_files_says_what_is_missing(prepared, raw_root):
    shutil.rmtree(raw_root / "trajnetpp_vita")
    with pytest.raises(PredictorError, match="--protocol loo needs the TrajNet"):
        protocol_files(prepared, "loo")


def test_raw_directory_is_prepared_once_into_the_cache(raw_root, monkeypatch, tmp_path):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    calls = []

    def fast_prepare(*args, **kwargs):
        calls.append(args)
        # no categorisation and no self-check: this test is about locating and caching
        return prepare_ewap(*args, **{**kwargs, "categorize_scenes": False, "references": {}})

    monkeypatch.setattr(locate, "prepare_ewap", fast_prepare)
    logged = []
    first = prepared_dir(raw_root, log=logged.append, progress=False)
    assert first.parent == tmp_path / "cache" / "prepared"
    # each file named where it ends up, not in the staging folders it is made in
    assert [line.rsplit(" -> ", 1)[1] for line in logged if " -> " in line] == [
        str(first / split / f"{name}.ndjson") for name in ("biwi_eth", "biwi_hotel") for split in SPLITS
    ]
    assert (first / "test" / "biwi_eth.ndjson").is_file()
    assert prepared_dir(raw_root / "raw_ewap", log=lambda msg: None) == first  # raw_ewap itself works too
    assert len(calls) == 1
    files = protocol_files(raw_root, "loo", log=lambda msg: None)
    assert files["test"] == [first / "test" / "biwi_eth.ndjson"]


def test_the_first_preparation_promises_no_time(raw_root, monkeypatch, tmp_path):
    """It said "(first use only; about half a minute)", where it took 41 s of CPU idle and 60 s of CPU and
    minutes of wall time under load: the machine decides, so the line says what takes the time."""
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    _fast_prepare(monkeypatch)
    logged: list[str] = []
    entry = prepared_dir(raw_root, log=logged.append, progress=False)
    assert logged[0] == (
        f"preparing {raw_root / 'raw_ewap'} into {entry} (first use only; this takes a while, longer on a "
        "busy machine: the TrajNet++ categorisation's Kalman fits, most of it)"
    )


def test_directory_without_data_is_explained(tmp_path):
    with pytest.raises(PredictorError, match="neither prepared splits"):
        prepared_dir(tmp_path)


@pytest.mark.parametrize("kind", ["fifo", "folder"])
def test_an_obsmat_that_is_no_regular_file_is_named(raw_root, kind):
    """`evaluate --data-dir D` with D/raw_ewap/seq_eth/obsmat.txt a FIFO said D "holds neither prepared
    splits ... nor raw BIWI EWAP annotations", as if nothing were there."""
    obsmat = raw_root / "raw_ewap" / "seq_eth" / "obsmat.txt"
    obsmat.unlink()
    os.mkfifo(obsmat) if kind == "fifo" else obsmat.mkdir()
    with pytest.raises(PredictorError) as refused:
        prepared_dir(raw_root)
    said = str(refused.value)
    assert said.startswith(f"{obsmat}: ") and said.endswith("(expected a BIWI EWAP obsmat.txt)")


def test_unknown_protocol_and_dataset(prepared):
    with pytest.raises(PredictorError, match="unknown protocol 'lofo'"):
        protocol_files(prepared, "lofo")
    with pytest.raises(PredictorError, match="unknown dataset 'zara'"):
        protocol_files(prepared, "paper", "zara")


def test_incomplete_prepared_directory_is_not_used(prepared):
    (prepared / "test" / "biwi_eth.ndjson").unlink()
    with pytest.raises(PredictorError, match=r"incomplete or unreadable \(lacks test/biwi_eth.ndjson\)"):
        protocol_files(prepared, "paper")
    (prepared / "manifest.json").write_text("{")  # unreadable: nothing to name
    with pytest.raises(PredictorError, match="incomplete or unreadable; re-run"):
        protocol_files(prepared, "paper")


@pytest.mark.parametrize(
    "text",
    ['{"format": "crowdmpc-prepared", "n": ' + "9" * 5000 + "}", "[" * 100_000],
    ids=["long-integer", "nested"],
)
def test_a_prepared_manifest_of_hostile_json_is_unreadable_not_a_traceback(prepared, text):
    """`crowdmpc evaluate --data-dir DIR` over a manifest.json holding a 5000-digit integer ended in
    "ValueError: Exceeds the limit (4300 digits)": load_manifest caught JSONDecodeError, not the ValueError
    json raises for such a number. It is now unreadable, as other damage is."""
    (prepared / "manifest.json").write_text(text)
    assert locate.load_manifest(prepared) is None
    with pytest.raises(PredictorError, match="incomplete or unreadable; re-run"):
        protocol_files(prepared, "paper")


def _fast_prepare(monkeypatch, then=None):
    """prepare_ewap without categorisation or self-check, counted; ``then(out)`` runs after each."""
    calls = []

    def fast_prepare(*args, **kwargs):
        calls.append(args)
        manifest = prepare_ewap(*args, **{**kwargs, "categorize_scenes": False, "references": {}})
        if then is not None:
            then(args[1])
        return manifest

    monkeypatch.setattr(locate, "prepare_ewap", fast_prepare)
    return calls


def test_a_damaged_cache_entry_is_prepared_again_and_replaced(raw_root, monkeypatch, tmp_path):
    """An edited file in the cached preparation made every run prepare again, then fail to rename onto the
    entry (directory not empty) in a traceback."""
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    calls = _fast_prepare(monkeypatch)
    entry = prepared_dir(raw_root, log=lambda msg: None, progress=False)
    good = (entry / "val" / "biwi_eth.ndjson").read_bytes()
    with (entry / "val" / "biwi_eth.ndjson").open("a") as damaged:
        damaged.write("junk\n")
    logged = []
    assert prepared_dir(raw_root, log=logged.append, progress=False) == entry
    assert "the cached one is damaged: val/biwi_eth.ndjson has " in logged[0]
    assert (entry / "val" / "biwi_eth.ndjson").read_bytes() == good
    assert locate.read_manifest(entry) is not None and len(calls) == 2
    assert prepared_dir(raw_root, log=lambda msg: None, progress=False) == entry and len(calls) == 2
    assert sorted(p.name for p in entry.parent.iterdir()) == sorted([entry.name, f".{entry.name}.lock"])


def test_a_good_cache_entry_installed_meanwhile_is_kept(raw_root, monkeypatch, tmp_path):
    """Another process that replaced the damaged entry while this one prepared: this one uses its entry."""
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    _fast_prepare(monkeypatch)
    entry = prepared_dir(raw_root, log=lambda msg: None, progress=False)
    theirs = tmp_path / "theirs"
    shutil.copytree(entry, theirs)
    (theirs / "installed-by-the-other").touch()
    (entry / "test" / "biwi_eth.ndjson").unlink()

    def the_other_finishes_first(staging):
        shutil.rmtree(entry)
        theirs.rename(entry)

    _fast_prepare(monkeypatch, then=the_other_finishes_first)
    assert prepared_dir(raw_root, log=lambda msg: None, progress=False) == entry
    assert (entry / "installed-by-the-other").exists() and locate.read_manifest(entry) is not None
    assert sorted(p.name for p in entry.parent.iterdir()) == sorted([entry.name, f".{entry.name}.lock"])


def test_two_preparations_of_one_cache_entry_at_once_prepare_once(raw_root, monkeypatch, tmp_path):
    """Two `train` runs started at once on an empty cache each prepared the same entry (40 s of CPU
    apiece, one entry left): the second now waits for the first's and takes it."""
    import threading

    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    first_preparing, second_waiting = threading.Event(), threading.Event()

    def hold_until_the_second_waits(out):
        first_preparing.set()
        second_waiting.wait(timeout=5)

    calls = _fast_prepare(monkeypatch, then=hold_until_the_second_waits)
    logs: dict[str, list[str]] = {"first": [], "second": []}
    entries: dict[str, object] = {}

    def second_log(msg):
        logs["second"].append(msg)
        if msg.startswith("waiting for another process"):
            second_waiting.set()

    def run(name, log):
        entries[name] = prepared_dir(raw_root, log=log, progress=False)

    first = threading.Thread(target=run, args=("first", logs["first"].append))
    first.start()
    assert first_preparing.wait(timeout=30)
    second = threading.Thread(target=run, args=("second", second_log))
    second.start()
    first.join(timeout=60)
    second.join(timeout=60)
    assert len(calls) == 1
    assert entries["first"] == entries["second"] and locate.read_manifest(entries["first"]) is not None
    assert [m.split(" ")[0] for m in logs["second"]] == ["waiting"]


def test_what_a_killed_preparation_left_in_the_cache_is_removed_by_the_next(raw_root, monkeypatch, tmp_path):
    """A preparation into the cache killed on the way left its staging folders there for good: each name holds
    its pid, so prepare_ewap's sweep of killed stagings (beside the folder the next process names, with that
    process's pid) never matched them. Those of a live process are kept."""
    import os
    import subprocess
    import sys

    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    _fast_prepare(monkeypatch)
    entry = prepared_dir(raw_root, log=lambda msg: None, progress=False)
    shutil.rmtree(entry)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True)
    gone, alive = int(dead.stdout), os.getppid()
    names = [f"{entry.name}.{{}}.tmp", f".{entry.name}.{{}}.tmp.prepare-{{}}.tmp", f".{entry.name}.{{}}.old"]
    for name in names:
        for pid in (gone, alive):
            (entry.parent / name.format(pid, pid)).mkdir()
            (entry.parent / name.format(pid, pid) / "biwi_eth.ndjson").write_text("half a preparation\n")
    assert prepared_dir(raw_root, log=lambda msg: None, progress=False) == entry
    kept = sorted([entry.name, f".{entry.name}.lock"] + [name.format(alive, alive) for name in names])
    assert sorted(p.name for p in entry.parent.iterdir()) == kept


def test_a_killed_lock_holders_staging_is_removed_by_the_waiter(raw_root, monkeypatch, tmp_path):
    """The waiter takes the entry's lock as the killed holder's descriptors close, before its parent reaps it:
    a zombie, which kill(pid, 0) finds, so its staging was taken for a live process's and kept for good."""
    import subprocess
    import sys
    import time

    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    _fast_prepare(monkeypatch)
    entry = prepared_dir(raw_root, log=lambda msg: None, progress=False)
    shutil.rmtree(entry)
    holder = subprocess.Popen([sys.executable, "-c", "pass"])  # ended, not yet reaped: a zombie
    stat = Path(f"/proc/{holder.pid}/stat")
    deadline = time.monotonic() + 30
    while " Z " not in stat.read_text(encoding="utf-8") and time.monotonic() < deadline:
        time.sleep(0.01)
    left = entry.parent / f".{entry.name}.{holder.pid}.tmp.prepare-{holder.pid}.tmp"
    left.mkdir()
    try:
        assert prepared_dir(raw_root, log=lambda msg: None, progress=False) == entry
    finally:
        holder.wait()
    assert sorted(p.name for p in entry.parent.iterdir()) == sorted([entry.name, f".{entry.name}.lock"])


def test_loo_of_a_raw_copy_finds_only_the_trajnet_files_beside_it(raw_root, monkeypatch, tmp_path):
    # the cache entry is shared by every copy of the same obsmat files: its source_dir is the first copy's
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(
        locate, "prepare_ewap", lambda *a, **k: prepare_ewap(*a, **{**k, "categorize_scenes": False})
    )
    protocol_files(raw_root, "loo", log=lambda msg: None)
    copy = tmp_path / "copy"
    shutil.copytree(raw_root / "raw_ewap", copy / "raw_ewap")
    with pytest.raises(PredictorError, match="--protocol loo needs the TrajNet"):
        protocol_files(copy, "loo", log=lambda msg: None)
    shutil.copytree(raw_root / "trajnetpp_vita", copy / "trajnetpp_vita")
    files = protocol_files(copy / "raw_ewap", "loo", log=lambda msg: None)
    assert files["train"][0] == copy / "trajnetpp_vita" / "train" / "real_data" / "crowds_zara01.ndjson"
