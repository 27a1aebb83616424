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


def _sweep(out, episodes: int) -> int:
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
    return main([*argv, "--episodes-per-cell", str(episodes), "--out", str(out), "--no-progress"])


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
