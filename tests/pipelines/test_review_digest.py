"""pipelines/logs/digest.py: a folder's review keeps a digest of each recording, not its messages."""

from __future__ import annotations

import gc
import json
import shutil
import weakref

import numpy as np
import pytest

from pipelines.cli import main
from pipelines.logs import reader
from pipelines.logs.digest import digest
from pipelines.logs.identity import run_identity
from pipelines.logs.reader import read_recording
from pipelines.logs.review import summarize
from pipelines.logs.schema_check import check_recording
from tests.pipelines.mcap_episode import cut_before_episode_metadata, record_episode


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Three finished 8-step episodes in one folder."""
    folder = tmp_path_factory.mktemp("runs")
    for seed in (1, 2, 3):
        record_episode(folder, seed=seed, steps=8)
    return folder


def test_a_digest_holds_what_the_review_uses(folder):
    rec = read_recording(sorted(folder.glob("*.mcap"))[0])
    run = digest(rec, check=True)
    assert run.summary == summarize(rec) and run.file == str(rec.path)
    assert run.identity == run_identity(rec.episode(), rec.config())
    # the recorded stand-in solves in 0.01 s x (step + 1): steps 0..7
    np.testing.assert_allclose(run.solve_times_s, 0.01 * np.arange(1, 9))
    assert run.check == check_recording(rec) and run.check[1] == []
    assert digest(rec).check is None  # checked only when asked
    assert (run.warning, run.problems_warning) == (rec.warning, rec.problems_warning) == (None, None)


def test_a_run_without_episode_metadata_has_no_set_up(folder):
    source = sorted(folder.glob("*.mcap"))[0]
    rec = read_recording(source)
    rec.metadata.pop("episode")
    assert digest(rec).identity is None


def test_a_folders_review_lets_each_recording_go_once_digested(folder, monkeypatch, capsys, tmp_path):
    """A recording takes ~5 MB in memory: a sweep's thousands held at once would not fit."""
    alive: list[weakref.ref] = []
    read = reader.read_recording

    def tracked(path):
        rec = read(path)
        alive.append(weakref.ref(rec))
        return rec

    monkeypatch.setattr(reader, "read_recording", tracked)
    held_at_the_end = []

    def summary_table(*args, **kwargs):  # the tables are made once every file was read
        gc.collect()
        held_at_the_end.append(sum(ref() is not None for ref in alive))
        return table(*args, **kwargs)

    from pipelines.logs import run_tables

    table = run_tables.aggregate_table
    monkeypatch.setattr(run_tables, "aggregate_table", summary_table)
    assert main(["review", str(folder), "--check", "--json", str(tmp_path / "r.json")]) == 0
    assert len(alive) == 3 and held_at_the_end == [0]
    out = capsys.readouterr().out
    assert out.count(" ok\n") == 3 and "over 24 steps; fallback steps 3" in out
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["totals"]["control_steps"] == 24
    # pooled over the three runs' steps: 0.01..0.08 s each, so the median is 45 ms and the maximum 80 ms
    assert report["totals"]["solve_time_median_ms"] == pytest.approx(45.0)
    assert report["totals"]["solve_time_max_ms"] == pytest.approx(80.0)


def test_a_folder_with_two_set_ups_pools_each_ones_steps_alone(folder, tmp_path, capsys):
    other = tmp_path / "other"
    other.mkdir()
    record_episode(other, seed=4, steps=5, n_humans=5)
    both = tmp_path / "both"
    shutil.copytree(folder, both / "a")
    shutil.copytree(other, both / "b")
    assert main(["review", str(both), "--json", str(tmp_path / "r.json")]) == 0
    groups = json.loads((tmp_path / "r.json").read_text())["groups"]
    assert [g["totals"]["control_steps"] for g in groups] == [24, 5]
    assert [g["totals"]["solve_time_max_ms"] for g in groups] == pytest.approx([80.0, 50.0])


def test_a_run_of_unknown_set_up_keeps_its_place_in_the_one_known_set_up(tmp_path, capsys):
    first = record_episode(tmp_path, seed=1, steps=4)
    (tmp_path / "a_cut.mcap").write_bytes(cut_before_episode_metadata(first.path.read_bytes()))
    record_episode(tmp_path, seed=2, steps=4)
    assert main(["review", str(tmp_path), "--json", str(tmp_path / "r.json")]) == 0
    (group,) = json.loads((tmp_path / "r.json").read_text())["groups"]
    names = ["a_cut.mcap", "circle_seed000001.mcap", "circle_seed000002.mcap"]
    assert group["files"] == [str(tmp_path / name) for name in names]  # the folder's order
    assert "\n3 runs, 1 whose episode did not end" in capsys.readouterr().out
