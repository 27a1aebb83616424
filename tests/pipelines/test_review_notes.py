"""crowdmpc review's warnings and checks that a new user's folders showed missing: copies of one episode,
subfolders left unread, a sweep's failures only, cut or damaged files under --check, uncommitted code, and
what --compare leaves unsaid."""

from __future__ import annotations

import json
import shutil
import struct

import pytest
from mcap.reader import make_reader

from pipelines.cli import main
from pipelines.logs.reader import read_recording
from pipelines.logs.recording import McapEpisodeRecorder
from tests.pipelines import mcap_episode
from tests.pipelines.mcap_episode import cut_before_episode_metadata, record_episode

WARNING = "crowdmpc review: warning:"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Three finished 4-step episodes in one folder."""
    folder = tmp_path_factory.mktemp("runs")
    return [record_episode(folder, seed=seed, steps=4) for seed in (1, 2, 3)]


def _warnings(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith(WARNING)]


def test_copies_of_one_episode_count_once_in_their_set_up(runs, tmp_path, capsys):
    """A folder holding a run's files and a backup of some of them (a/ and b/) pooled both: "collision 38.5 %
    (5/13)" where the 10 episodes had 3. Each episode counts once, the copies named in one warning."""
    for run in runs:
        shutil.copy(run.path, (tmp_path / "a").mkdir(exist_ok=True) or tmp_path / "a" / run.path.name)
    (tmp_path / "b").mkdir()
    for run in runs[1:]:
        shutil.copy(run.path, tmp_path / "b" / run.path.name)
    assert main(["review", str(tmp_path), "--json", str(tmp_path / "r.json")]) == 0
    out, err = capsys.readouterr()
    (warning,) = _warnings(err)
    kept, copy = tmp_path / "a" / runs[1].path.name, tmp_path / "b" / runs[1].path.name
    assert "holds 2 repeats of episodes of" in warning and f"e.g. {copy} repeats {kept}" in warning
    assert "\n3 runs\n" in out and f"b/{runs[1].path.name}" not in out
    report = json.loads((tmp_path / "r.json").read_text())
    (group,) = report["groups"]
    assert report["totals"]["runs"] == 3 and len(group["files"]) == 3
    assert group["repeats"] == {
        str(copy): str(kept),
        str(copy.with_name(runs[2].path.name)): str(kept.with_name(runs[2].path.name)),
    }
    assert len(report["runs"]) == 5  # every file read is listed: files, not episodes


def test_a_copy_whose_episode_ended_is_the_one_kept(runs, tmp_path, capsys):
    data = runs[0].path.read_bytes()
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / runs[0].path.name).write_bytes(data[: len(data) // 3])  # a killed run's file
    (tmp_path / "b").mkdir()
    shutil.copy(runs[0].path, tmp_path / "b" / runs[0].path.name)
    assert main(["review", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    assert f"{tmp_path}/a/{runs[0].path.name} repeats {tmp_path}/b/{runs[0].path.name}" in err
    assert "\n1 run\n" in out


def test_an_undamaged_copy_is_kept_before_a_damaged_one(tmp_path, capsys):
    """Of two copies of one episode, the first in path order was kept though a flipped byte had cost it a
    chunk: the table's solve times were over the steps that chunk left, where the other copy held all."""
    run = record_episode(tmp_path / "runs", seed=1, steps=20)
    data = run.path.read_bytes()
    with run.path.open("rb") as f:
        chunk = make_reader(f).get_summary().chunk_indexes[1]
    bad = bytearray(data)
    bad[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0x10  # inside its compressed records
    copies = tmp_path / "copies"
    damaged, intact = copies / "a" / run.path.name, copies / "b" / run.path.name
    for path, content in ((damaged, bytes(bad)), (intact, data)):
        path.parent.mkdir(parents=True)
        path.write_bytes(content)
    assert read_recording(damaged).problems[0].startswith("bad chunk at byte")
    assert main(["review", str(copies), "--json", str(tmp_path / "r.json")]) == 0
    err = capsys.readouterr().err
    assert f"e.g. {damaged} repeats {intact}" in err
    (group,) = json.loads((tmp_path / "r.json").read_text())["groups"]
    assert group["files"] == [str(intact)]
    assert group["totals"]["control_steps"] == 20


def test_a_folder_with_files_of_its_own_says_its_subfolders_are_not_read(runs, tmp_path, capsys):
    shutil.copy(runs[0].path, tmp_path / runs[0].path.name)
    for name, run in (("x", runs[1]), ("y/z", runs[2])):
        (tmp_path / name).mkdir(parents=True)
        shutil.copy(run.path, tmp_path / name / run.path.name)
    assert main(["review", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    assert "\n1 run\n" in out  # the rule stands: the folder's own files
    assert f"{WARNING} {tmp_path}: its subfolders hold 2 recordings, not read with " in err
    assert err.rstrip().endswith("review each subfolder")


def test_a_folder_of_only_unfinished_files_names_its_subfolders_recordings(runs, tmp_path, capsys):
    data = runs[0].path.read_bytes()
    (tmp_path / "cut.mcap.part").write_bytes(data[: len(data) // 2])
    (tmp_path / "sub").mkdir()
    shutil.copy(runs[1].path, tmp_path / "sub" / runs[1].path.name)
    assert main(["review", str(tmp_path)]) == 2
    err = capsys.readouterr().err.splitlines()[-1]
    assert err.startswith(f"crowdmpc review: error: no readable recording in {tmp_path} (0 unreadable, 1 unf")
    assert "; its subfolders hold 1 recording, not read with" in err


def test_recordings_deeper_than_two_levels_are_named_in_the_error(runs, tmp_path, capsys):
    """A folder of two sweeps: DIR/a/mcap/CELL/*.mcap is three levels below DIR, past what a review reads."""
    for sweep in ("a", "b"):
        cell = tmp_path / sweep / "mcap" / "cell"
        cell.mkdir(parents=True)
        shutil.copy(runs[0].path, cell / runs[0].path.name)
    assert main(["review", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "nor in the two levels of folders below it; deeper folders hold 2 recordings " in err
    assert f"(under {tmp_path / 'a'}, {tmp_path / 'b'}): review each of those folders" in err
    assert main(["review", str(tmp_path / "a")]) == 0  # each one reviews


def test_a_sweep_without_recordings_is_said_to_record_none(tmp_path, capsys):
    """`review SWEEP` of a sweep run without --record said only "no .mcap files"."""
    (tmp_path / "sweep.json").write_text("{}")
    assert main(["review", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert (
        err.count("\n") == 1 and "nor in the two levels of folders below it; it is a sweep's, which " in err
    )
    assert "records episodes only with `sweep --record all|failures`" in err


def test_a_sweep_records_which_episodes_it_kept_in_each_file(tmp_path):
    argv = ["sweep", "--experiment", "baselines", "--humans", "3", "--episodes-per-cell", "1"]
    out = tmp_path / "o"
    assert main([*argv, "--backend", "inline", "--record", "all", "--no-progress", "--out", str(out)]) == 0
    files = sorted(out.glob("mcap/*/*.mcap"))
    assert files and {read_recording(f).run_meta()["record"] for f in files} == {"all"}


def test_a_sweeps_failures_only_say_so_from_the_files_alone(runs, tmp_path, capsys, monkeypatch):
    """`sweep --record failures` keeps the failed episodes only; review warned only where it found sweep.json
    above the files. The files say it themselves, once for the folder."""

    class SweepRecorder(McapEpisodeRecorder):
        def __init__(self, *args, run_meta=None, **kwargs):
            meta = {"experiment": "table2", "cell": "cmpc", "record": "failures"}
            super().__init__(*args, run_meta=meta, **kwargs)

    monkeypatch.setattr(mcap_episode, "McapEpisodeRecorder", SweepRecorder)
    for seed in (1, 2):
        record_episode(tmp_path / "copied", seed=seed, steps=4)
    assert main(["review", str(tmp_path / "copied")]) == 0
    (warning,) = _warnings(capsys.readouterr().err)
    assert f"2 of the 2 recordings in {tmp_path / 'copied'} (e.g. " in warning
    assert "are a sweep's failed episodes only (sweep --record failures" in warning
    assert main(["review", str(runs[0].path.parent)]) == 0  # recordings of simulate: nothing to say
    assert "failed episodes" not in capsys.readouterr().err


def test_compare_with_check_checks_both_files(runs, tmp_path, capsys):
    data = runs[1].path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    assert main(["review", str(runs[0].path), "--compare", str(cut), "--check"]) == 1
    out = capsys.readouterr().out
    assert f"check {runs[0].path}: " in out and f"check {cut}: " in out and " truncated: " in out
    assert main(["review", str(runs[0].path), "--compare", str(runs[1].path), "--check"]) == 0
    assert capsys.readouterr().out.count(" messages, ok\n") == 2


def test_check_fails_a_cut_file_and_counts_the_files_problems_apart(runs, tmp_path, capsys):
    """A file cut with `head -c` passed --check ("ok"); a corrupt summary record counted as "1 invalid"
    message. Each is a line of its own, and the messages' count is theirs alone."""
    data = runs[0].path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    n_read = sum(len(m) for m in read_recording(cut).messages.values())
    assert main(["review", str(cut), "--check", "--json", str(tmp_path / "r.json")]) == 1
    out = capsys.readouterr().out
    assert f"check {cut}: {n_read} messages read, truncated: " in out
    entry = json.loads((tmp_path / "r.json").read_text())["check"][str(cut)]
    assert entry["truncated"] and entry["errors"] == [] and entry["file_problems"] == []

    # the footer (opcode, length, summary start, summary offset start, CRC) points at the summary offsets;
    # a huge length in the first of them is a corrupt record of a file that is otherwise complete
    footer = len(data) - 8 - 29
    offsets_start = struct.unpack_from("<Q", data, footer + 17)[0]
    bad = bytearray(data)
    struct.pack_into("<Q", bad, offsets_start + 1, 1 << 40)
    corrupt = tmp_path / "corrupt.mcap"
    corrupt.write_bytes(bytes(bad))
    assert main(["review", str(corrupt), "--check"]) == 1
    out = capsys.readouterr().out
    lines = out[out.index("\ncheck ") + 1 :].splitlines()
    checked = sum(len(m) for m in read_recording(corrupt).messages.values())
    assert lines[0] == f"check {corrupt}: the file itself: 1 problem"
    assert lines[1].startswith("  corrupt record at byte ")
    assert lines[2] == f"check {corrupt}: {checked} messages, each valid; fails: its own problems"


def test_a_recording_of_uncommitted_code_says_dirty(tmp_path, capsys, monkeypatch):
    """crowdmpc.dirty = "true" showed as "commit c28989d46c28" like a clean one, and the mixed-code warning
    took clean and dirty recordings of one commit for the same code."""
    import pipelines.logs.recording as recording
    from pipelines.plugins import code_with_plugins

    now = code_with_plugins()
    for seed, dirty in ((1, False), (2, True)):
        diff = "ab" * 32 if dirty else None
        monkeypatch.setattr(
            recording,
            "code_with_plugins",
            lambda d=dirty, s=diff: {**now, "commit": "c28989d46c28abcd", "dirty": d, "diff_sha256": s},
        )
        record_episode(tmp_path, seed=seed, steps=4)
    monkeypatch.undo()
    assert main(["review", str(tmp_path), "--json", str(tmp_path / "r.json")]) == 0
    (warning,) = _warnings(capsys.readouterr().err)
    assert "recorded by different code (commit c28989d46c28, commit c28989d46c28+dirty:abababab)" in warning
    report = json.loads((tmp_path / "r.json").read_text())
    assert [r["crowdmpc_dirty"] for r in report["runs"]] == [False, True]
    (dirty,) = tmp_path.glob("*seed000002.mcap")
    assert main(["review", str(dirty)]) == 0
    (line,) = [line for line in capsys.readouterr().out.splitlines() if line.startswith("crowdmpc ")]
    assert line.endswith("(commit c28989d46c28+dirty:abababab)")


def test_compare_lists_the_settings_that_differ_and_warns_of_another_crowd(tmp_path, capsys):
    a = record_episode(tmp_path / "a", seed=1, steps=4, config={"mpc": {"w_coll": 1e7}})
    b = record_episode(tmp_path / "b", seed=2, steps=4, n_humans=5, config={"mpc": {"w_coll": 1e6}})
    assert main(["review", str(a.path), "--compare", str(b.path), "--json", str(tmp_path / "r.json")]) == 0
    (warning,) = _warnings(capsys.readouterr().err)
    assert "are episodes of different crowds (seed 1 vs 2, humans 4 vs 5)" in warning
    compare = json.loads((tmp_path / "r.json").read_text())["compare"]
    assert compare["file"] == str(b.path)
    assert {"setting": "mpc.w_coll", "a": 1e7, "b": 1e6} in compare["differing_settings"]
    c = record_episode(tmp_path / "c", seed=1, steps=4, config={"mpc": {"w_coll": 1e6}})
    assert main(["review", str(a.path), "--compare", str(c.path)]) == 0
    assert "different crowds" not in capsys.readouterr().err  # one crowd, another controller setting


def test_compare_with_a_recording_that_names_no_crowd_says_so(tmp_path, capsys):
    """A recording killed before its metadata was written was said to hold another crowd, "scenario None vs
    circle, seed None vs 1, humans None vs 4"."""
    a = record_episode(tmp_path / "a", seed=1, steps=4)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(cut_before_episode_metadata(a.path.read_bytes()))
    assert main(["review", str(a.path), "--compare", str(cut)]) == 0
    err = capsys.readouterr().err
    assert "None" not in err
    assert (
        f"{a.path} and {cut} may be episodes of different crowds ({cut} records no scenario, seed or humans)"
        in err
    )


def test_compare_with_animate_is_refused_before_reading(runs, tmp_path, capsys):
    argv = ["review", str(runs[0].path), "--compare", str(runs[1].path), "--animate", str(tmp_path / "a.gif")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err == (
        "crowdmpc review: error: --animate animates one run, not --compare's two; animate each on its own\n"
    )
    assert not (tmp_path / "a.gif").exists()


def test_a_gym_loops_episodes_of_one_seed_each_count(tmp_path, capsys):
    """A gym loop resetting to one seed with another policy records each episode in its own file
    (``circle_seed000003_1.mcap``), yet the folder's review left the second out as a copy of the first:
    "1 run" for two episodes that drove apart. Copies of either file still count once."""
    import numpy as np

    from pipelines.loop.gym_loop import ObserveEpisodes, make_env

    runs = tmp_path / "runs"
    with McapEpisodeRecorder(runs) as recorder:
        env = ObserveEpisodes(make_env(None, n_humans=2, n_robots=1), [recorder])
        for acceleration in (0.5, -0.5):
            env.reset(seed=3)
            for _ in range(3):
                env.step(np.full(env.action_space.shape, acceleration))
        env.close()
    first, second = recorder.paths
    assert second.name == "circle_seed000003_1.mcap"
    assert main(["review", str(runs)]) == 0
    out, err = capsys.readouterr()
    assert "\n2 runs\n" in out and not _warnings(err)
    backup = tmp_path / "backup"
    backup.mkdir()
    shutil.copy(second, backup / second.name)
    assert main(["review", str(tmp_path), "--json", str(tmp_path / "r.json")]) == 0
    out, err = capsys.readouterr()
    (group,) = json.loads((tmp_path / "r.json").read_text())["groups"]
    assert group["repeats"] == {str(runs / second.name): str(backup / second.name)}
    assert "\n2 runs\n" in out
