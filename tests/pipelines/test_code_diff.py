"""Two runs of one commit with different uncommitted changes recorded the same code ("commit ...,
dirty: true"): the identity now names the diff by its sha256, shown as "+dirty:0123abcd", and a resume
after the diff changed says so."""

from __future__ import annotations

import hashlib
import subprocess

import pytest

from pipelines import version
from pipelines.experiments.compare_sources import commit_text
from pipelines.logs.review import commit_shown


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
