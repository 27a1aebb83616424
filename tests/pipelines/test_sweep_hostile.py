"""A sweep directory that was damaged or edited by hand stops the sweep with one line naming the file (and
the line), never a traceback, and nothing of it is overwritten."""

import json
from pathlib import Path

import pytest

from pipelines.cli import main
from pipelines.errors import PipelineError
from pipelines.experiments.cells import get_experiment
from pipelines.experiments.log import EPISODES_FILE, SWEEP_FILE, episode_log
from pipelines.experiments.sweep import SweepConfig, run_sweep

ARGV = ["sweep", "--experiment", "baselines", "--humans", "3", "--episodes-per-cell", "1", "--backend",
        "inline", "--no-progress", "--jit", "off"]  # fmt: skip


def _config(out: Path) -> SweepConfig:
    return SweepConfig(get_experiment("baselines"), out, 1, humans=(3,), backend="inline", progress=False)


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("good")
    run_sweep(_config(out))
    return out


@pytest.mark.parametrize(
    "content",
    [b"{not json", b"\xff\xfe", b"[1, 2]", b'{"runs": 3}', b"[" * 100_000 + b"]" * 100_000],
    ids=["broken", "not-utf8", "a-list", "runs-not-a-list", "deep"],
)
def test_a_garbage_sweep_file_is_named_and_left_alone(tmp_path, capsys, content):
    (tmp_path / SWEEP_FILE).write_bytes(content)
    assert main([*ARGV, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{tmp_path / SWEEP_FILE}: not a sweep file" in err[0]
    assert (tmp_path / SWEEP_FILE).read_bytes() == content


def test_a_sweep_file_that_is_a_folder_is_named(tmp_path):
    (tmp_path / SWEEP_FILE).mkdir()
    with pytest.raises(PipelineError, match=f"{tmp_path / SWEEP_FILE}: not a sweep file"):
        run_sweep(_config(tmp_path))


def _damage(good: Path, tmp_path: Path, edit) -> Path:
    lines = (good / EPISODES_FILE).read_text().splitlines()
    records = [json.loads(line) for line in lines]
    edit(records[0])
    (tmp_path / EPISODES_FILE).write_text("".join(json.dumps(r) + "\n" for r in records))
    return tmp_path / EPISODES_FILE


@pytest.mark.parametrize(
    ("edit", "reason"),
    [
        (lambda r: r.pop("metrics"), "not an episode record"),
        (lambda r: r.update(metrics="fine"), "not an episode record"),
        (lambda r: r["solver"].pop("steps"), "not an episode record"),
        (lambda r: r.update(seed="seven"), "not an episode record"),
        (lambda r: r.update(index=True), "'index' is not an integer"),
        (lambda r: r.update(cell=None), "'cell' is not a string"),
    ],
    ids=["no-metrics", "metrics-string", "solver-incomplete", "seed-string", "index-bool", "cell-null"],
)
def test_a_damaged_record_is_named_by_file_and_line(good, tmp_path, edit, reason):
    path = _damage(good, tmp_path, edit)
    before = path.read_bytes()
    with pytest.raises(PipelineError, match=rf"{path}:1: .*{reason}.*the file is damaged"):
        episode_log(tmp_path).load()
    assert path.read_bytes() == before  # not repaired away: a damaged line is the user's to look at


def test_the_records_a_sweep_writes_pass_the_check(good):
    assert len(episode_log(good).load()) == 2
