"""Two runs of one commit with different uncommitted changes recorded the same code ("commit ...,
dirty: true"): the identity now names the diff by its sha256, shown as "+dirty:0123abcd", and a resume
after the diff changed says so. compare names a run's plugin files beside its commit."""

from __future__ import annotations

import hashlib
import json
import subprocess

import pytest

from pipelines import version
from pipelines.cli import main
from pipelines.experiments.compare_sources import commit_text
from pipelines.logs.identity import recorded_plugins
from pipelines.logs.review import commit_shown
from tests.pipelines.test_compare import BASE, _record, _simulate_json, _sweep


@pytest.fixture
def repo(tmp_path):
    if subprocess.run(["git", "--version"], capture_output=True).returncode != 0:
        pytest.skip("git is not installed")
    git = ["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git[:3], "init", "-q"], check=True)
    (tmp_path / "a.py").write_text("x = 1\n")
    subprocess.run([*git, "add", "a.py"], check=True)
    subprocess.run([*git, "commit", "-q", "-m", "a"], check=True)
    return tmp_path


def test_the_diff_of_a_dirty_tree_is_named_by_its_sha256(repo):
    (repo / "a.py").write_text("x = 2\n")
    diff = subprocess.run(["git", "-C", str(repo), "diff", "HEAD", "--binary"], capture_output=True).stdout
    assert version._diff_sha256(repo) == hashlib.sha256(diff).hexdigest()
    first = version._diff_sha256(repo)
    (repo / "a.py").write_text("x = 3\n")
    second = version._diff_sha256(repo)
    assert second not in (None, first)  # another change, another name
    (repo / "new.py").write_text("untracked\n")  # no part of the code a clone has
    assert version._diff_sha256(repo) == second


def test_a_dirty_commit_is_shown_with_its_diff():
    code = {"commit": "0123456789abcdef", "dirty": True, "diff_sha256": "89abcdef" + "0" * 56}
    assert commit_text(code) == "0123456789ab+dirty:89abcdef"
    assert commit_text(code | {"diff_sha256": None}) == "0123456789ab+dirty"  # recorded before the diff was
    assert commit_text(code | {"dirty": False, "diff_sha256": None}) == "0123456789ab"
    summary = {
        "crowdmpc_commit": "0123456789abcdef",
        "crowdmpc_dirty": True,
        "crowdmpc_diff_sha256": "fe" * 32,
    }
    assert commit_shown(summary) == "0123456789ab+dirty:fefefefe"


def test_a_resume_after_the_uncommitted_changes_changed_says_so():
    now = {"version": "0.1.0", "commit": "c" * 40, "dirty": True, "diff_sha256": "b" * 64, "python": "3.11"}
    assert version.code_changes([now], now) == ""
    changed = version.code_changes([now | {"diff_sha256": "a" * 64}], now)
    assert changed == f"diff_sha256 {'a' * 12} -> {'b' * 12}"
    older = {k: v for k, v in now.items() if k != "diff_sha256"}  # recorded before the diff was: unknown
    assert version.code_changes([older], now) == ""


def test_runs_of_one_commit_and_two_versions_of_a_plugin_name_both(tmp_path, capsys):
    """`crowdmpc compare none=runs/swap cp=runs/swap_cp` of two sweeps of one commit whose plugin net's file
    had changed between them (code.plugins in sweep.json, in simulate's JSON and a recording's metadata)
    showed "code 108081654bd7" for both: a comparison of two versions of a user's net read as of one code."""
    before, after = (
        {"attn_gru:AttnGRU": "c8d3fb46b1dd" + "0" * 52},
        {"attn_gru:AttnGRU": "b6ebe69bf509" + "1" * 52},
    )
    folders = []
    for name, plugins in (("before", before), ("after", after)):
        path = _sweep(tmp_path / name, [_record(i, *o) for i, o in enumerate(BASE)])
        code = {"commit": "0123456789abcdef", "dirty": False, "plugins": plugins}
        (path / "sweep.json").write_text(json.dumps({"experiment": "table2", "runs": [{"code": code}]}))
        folders.append(path)
    sim = _simulate_json(tmp_path / "run.json", [_record(i, *o) for i, o in enumerate(BASE)])
    document = json.loads(sim.read_text())
    document["code"]["plugins"] = after
    sim.write_text(json.dumps(document))
    out = tmp_path / "c.json"
    assert main(["compare", f"a={folders[0]}", f"b={folders[1]}", f"c={sim}", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"a: {folders[0]}, 4 episodes, code 0123456789ab (plugin attn_gru:AttnGRU c8d3fb46b1dd)" in text
    assert f"b: {folders[1]}, 4 episodes, code 0123456789ab (plugin attn_gru:AttnGRU b6ebe69bf509)" in text
    assert f"c: {sim}, 4 episodes, code fedcba987654+dirty (plugin attn_gru:AttnGRU b6ebe69bf509)" in text
    assert json.loads(out.read_text())["runs"][1]["code"] == [
        "0123456789ab (plugin attn_gru:AttnGRU b6ebe69bf509)"
    ]
    # a recording's "crowdmpc" metadata holds the plugins as JSON text; a run without plugins shows none
    meta = {"commit": "0123456789abcdef", "dirty": False, "plugins": json.dumps(before)}
    assert commit_text(meta) == "0123456789ab (plugin attn_gru:AttnGRU c8d3fb46b1dd)"
    assert (
        commit_text(meta | {"plugins": "{}"}) == commit_text(meta | {"plugins": "not json"}) == "0123456789ab"
    )


def test_recordings_of_one_commit_with_other_uncommitted_changes_show_their_diffs(
    tmp_path, monkeypatch, capsys
):
    """`crowdmpc compare a=DIR b=DIR` of two `simulate --record` runs of one commit with different uncommitted
    changes showed "code 0123456789ab+dirty" for both, where a sweep's code names the diff: the recordings'
    metadata holds its sha256. One recorded before it was (no diff_sha256) shows "+dirty" alone, as before."""
    from pipelines.logs import recording

    identity = {"version": "0.1.0", "commit": "0123456789abcdef", "dirty": True}
    runs = {
        "a": {"diff_sha256": "aaaaaaaa" + "0" * 56},
        "b": {"diff_sha256": "bbbbbbbb" + "1" * 56},
        "old": {},
    }
    run = ["simulate", "--controller", "cmpc", "--predictor", "constant_velocity", "--humans", "2"]
    run += ["--episodes", "1", "--seed", "4", "--no-progress", "--record"]
    for name, diff in runs.items():
        monkeypatch.setattr(recording, "code_with_plugins", lambda diff=diff: identity | diff)
        assert main([*run, str(tmp_path / name)]) == 0
    capsys.readouterr()
    assert main(["compare", *(f"{name}={tmp_path / name}" for name in runs), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert f"a: {tmp_path / 'a'}, 1 episode, code 0123456789ab+dirty:aaaaaaaa\n" in out
    assert f"b: {tmp_path / 'b'}, 1 episode, code 0123456789ab+dirty:bbbbbbbb\n" in out
    assert f"old: {tmp_path / 'old'}, 1 episode, code 0123456789ab+dirty\n" in out


def test_recorded_plugins_nested_past_the_stack_name_no_plugins(tmp_path, capsys):
    """The plugins' JSON text (a recording's metadata, or a sweep.json edited by hand) was parsed catching
    ValueError alone: text nested past json's recursion ended `crowdmpc compare` in a RecursionError."""
    deep = "[" * 100_000 + "]" * 100_000
    meta = {"commit": "0123456789abcdef", "dirty": False, "plugins": deep}
    assert commit_text(meta) == "0123456789ab"
    assert recorded_plugins(deep) is None
    path = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    (path / "sweep.json").write_text(json.dumps({"experiment": "table2", "runs": [{"code": meta}]}))
    other = _sweep(tmp_path / "b", [_record(i, *o) for i, o in enumerate(BASE)])
    assert main(["compare", f"a={path}", f"b={other}"]) == 0
    assert f"a: {path}, 4 episodes, code 0123456789ab\n" in capsys.readouterr().out


def test_code_without_a_git_commit_is_named_by_its_versions_as_the_table_names_it(
    tmp_path, monkeypatch, capsys
):
    """A run of an installed wheel or a `ray job submit` copy (Ray's upload leaves .git out) records its
    version, Python and libraries but no commit: compare said "code not recorded", as of a run from before
    code was kept, where table.md says "no git commit, crowdmpc 0.1.0, ...". Now both say the latter, of a
    sweep, a simulate --json file and recordings alike; a run with no code record still reads "not
    recorded"."""
    from pipelines.commands.sweep_table_notes import code_note
    from pipelines.logs import recording

    versions = {"version": "0.1.0", "python": "3.11.7", "casadi": "3.8.2", "torch": "2.13.0+cpu"}
    code = {**versions, "numpy": "2.4.6", "commit": None, "dirty": None, "diff_sha256": None}
    said = "no git commit, crowdmpc 0.1.0, Python 3.11.7, CasADi 3.8.2, torch 2.13.0+cpu, numpy 2.4.6"
    sweep = _sweep(tmp_path / "sweep", [_record(i, *o) for i, o in enumerate(BASE)])
    (sweep / "sweep.json").write_text(json.dumps({"experiment": "table2", "runs": [{"code": code}]}))
    sim = _simulate_json(tmp_path / "run.json", [_record(i, *o) for i, o in enumerate(BASE)])
    sim.write_text(json.dumps({**json.loads(sim.read_text()), "code": code}))
    records = [_record(i, *o) for i, o in enumerate(BASE)]
    none = _sweep(tmp_path / "none", records, commit=None)  # no sweep.json: nothing of its code
    assert main(["compare", f"a={sweep}", f"b={sim}", f"c={none}", "--json", str(tmp_path / "c.json")]) == 0
    out = capsys.readouterr().out
    assert f"a: {sweep}, 4 episodes, code {said}\n" in out and f"b: {sim}, 4 episodes, code {said}\n" in out
    assert f"c: {none}, 4 episodes, code not recorded\n" in out
    runs = json.loads((tmp_path / "c.json").read_text())["runs"]
    assert [run["code"] for run in runs] == [[said], [said], []]
    assert code_note(sweep) == f"Code: {said}."  # the same words
    assert commit_text({"commit": None}) is None and commit_text(None) is None  # nothing of the code

    monkeypatch.setattr(recording, "code_with_plugins", lambda: code)  # a wheel's recording
    run = ["simulate", "--controller", "cmpc", "--predictor", "constant_velocity", "--humans", "2"]
    run += ["--episodes", "1", "--seed", "4", "--no-progress", "--record", str(tmp_path / "r")]
    assert main(run) == 0
    capsys.readouterr()
    assert main(["compare", f"r={tmp_path / 'r'}", f"r2={tmp_path / 'r'}", "--no-progress"]) == 0
    assert f"r: {tmp_path / 'r'}, 1 episode, code {said}\n" in capsys.readouterr().out


def test_a_wheel_resuming_runs_of_unrecorded_or_git_code_names_what_it_is(tmp_path, capsys, monkeypatch):
    """An installed wheel (no git checkout: commit None) resuming a sweep recorded before the code was said
    "code not recorded -> commit None", and one recorded by a clone "commit 0123456789ab -> None": a commit
    of that name, where this install has none and is known by its versions."""
    wheel = {"version": "0.1.0", "commit": None, "dirty": None, "diff_sha256": None, "python": "3.11.7"}
    wheel |= {"casadi": "3.6.7", "torch": "2.5.1", "numpy": "2.1.3"}
    assert version.code_changes([None], wheel) == (
        "code not recorded -> (no git commit, crowdmpc 0.1.0, Python 3.11.7, CasADi 3.6.7, torch 2.5.1, "
        "numpy 2.1.3)"
    )
    clone = wheel | {"commit": "0123456789abcdef", "dirty": False}
    assert version.code_changes([clone], wheel) == "commit 0123456789ab -> (no git commit)"
    assert version.code_changes([wheel], clone) == "commit (no git commit) -> 0123456789ab"
    assert version.code_changes([None], clone) == "code not recorded -> commit 0123456789ab"
    # as the sweep's resume note says it
    from tests.pipelines.test_table_code import ARGV

    out = tmp_path / "s"
    assert main([*ARGV, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    meta = json.loads((out / "sweep.json").read_text())
    del meta["runs"][0]["code"]
    (out / "sweep.json").write_text(json.dumps(meta))
    installed = version.code_identity() | wheel
    monkeypatch.setattr(version, "code_identity", lambda: installed)
    capsys.readouterr()
    assert main([*ARGV, "--episodes-per-cell", "2", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "(code not recorded -> (no git commit, crowdmpc 0.1.0, Python 3.11.7, " in err
    assert "None" not in err
