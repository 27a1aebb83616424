"""A replayed crowd's recording is part of what a sweep's records state: the same --crowd from another
$CROWDMPC_DATA (or an edited obsmat.txt) replays other people, and a resume appended their episodes to the
cell silently, with nothing in the records to tell them apart."""

import json
import shutil

import pytest

from pipelines.cli import main
from tests.predictors.samples import shared_data_dir


@pytest.fixture
def own_data(tmp_path, monkeypatch):
    """A copy of the shared raw BIWI files (outside the project) that the test may edit."""
    root = shared_data_dir()
    if root is None:
        pytest.skip("shared data (../shared/data or $CROWDMPC_DATA) not available")
    copy = tmp_path / "data"
    shutil.copytree(root / "raw_ewap", copy / "raw_ewap")
    monkeypatch.setenv("CROWDMPC_DATA", str(copy))
    return copy


def _sweep(out, episodes: int, *more: str) -> int:
    argv = [
        "sweep",
        "--experiment",
        "baselines",
        "--crowd",
        "eth_test",
        "--humans",
        "5",
        "--backend",
        "inline",
    ]
    return main([*argv, "--episodes-per-cell", str(episodes), "--out", str(out), "--no-progress", *more])


def test_a_resume_with_another_recording_is_refused(own_data, tmp_path, capsys):
    import hashlib

    out = tmp_path / "s"
    assert _sweep(out, 1) == 0
    obsmat = own_data / "raw_ewap" / "seq_eth" / "obsmat.txt"
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert {r["crowd_sha256"] for r in records} == {hashlib.sha256(obsmat.read_bytes()).hexdigest()}
    assert _sweep(out, 2) == 0  # the same data: resumed
    capsys.readouterr()
    obsmat.write_text(obsmat.read_text().replace("\n", " \n", 1))  # one more byte: another file
    assert _sweep(out, 3) == 2
    err = capsys.readouterr().err
    assert "replaying people from a file of sha256" in err and f"{obsmat} is now" in err
    assert len((out / "episodes.jsonl").read_text().splitlines()) == len(records) * 2  # nothing appended


def test_a_simulate_run_names_its_replayed_file_and_compare_reads_it(own_data, tmp_path, capsys):
    """simulate's JSON and recordings named no ``crowd_sha256``, so compare said "(not recorded)" for their
    crowd beside a sweep's, and two simulate runs replaying two files read as one crowd. ``run`` names it
    now, in the JSON and in each recording's "run" metadata (a sweep's too), and compare reads both."""
    import hashlib

    from pipelines.logs.reader import read_recording

    obsmat = own_data / "raw_ewap" / "seq_eth" / "obsmat.txt"
    argv = ["simulate", "--controller", "orca", "--crowd", "eth_test", "--humans", "5", "--no-progress"]
    assert main([*argv, "--json", str(tmp_path / "a.json"), "--record", str(tmp_path / "rec")]) == 0
    assert _sweep(tmp_path / "s", 1, "--record", "all") == 0
    sha256 = hashlib.sha256(obsmat.read_bytes()).hexdigest()
    assert json.loads((tmp_path / "a.json").read_text())["run"]["crowd_sha256"] == sha256
    files = [*(tmp_path / "rec").glob("*.mcap"), *(tmp_path / "s" / "mcap").glob("*/*.mcap")]
    assert len(files) == 3  # simulate's, and the sweep's ORCA and straight-line episodes
    assert {read_recording(file).run_meta()["crowd_sha256"] for file in files} == {sha256}
    capsys.readouterr()
    for run in (tmp_path / "a.json", tmp_path / "rec"):  # the sweep's ORCA column: the same file
        assert main(["compare", str(tmp_path / "s"), str(run), "--no-progress"]) == 0
        assert "crowd_sha256" not in capsys.readouterr().out
    obsmat.write_text(obsmat.read_text().replace("\n", " \n", 1))  # the same people from another file
    assert main([*argv, "--json", str(tmp_path / "b.json")]) == 0
    out = ["--json", str(tmp_path / "c.json"), "--no-progress"]
    assert main(["compare", str(tmp_path / "a.json"), str(tmp_path / "b.json"), *out]) == 0
    (differ,) = json.loads((tmp_path / "c.json").read_text())["settings_differ"]["b"]
    now = hashlib.sha256(obsmat.read_bytes()).hexdigest()
    assert differ == {"setting": "crowd_sha256", "first": json.dumps(sha256), "this": json.dumps(now)}
