"""A file system that does not lock files (an NFS mount without its lock daemon: flock fails with ENOLCK):
the compile cache and calibrate's journal said so in a traceback, and the cleanups that ask whether a writer
still holds its lock file could not tell. The sweep's --out and predictors.locking.locked are tested beside
their commands."""

import errno
import fcntl
import os
from pathlib import Path

import pytest

from mpc import cache_entries, compile_cache
from pipelines.errors import PipelineError
from predictors import locking
from tests.mpc.test_compile_cache import IPOPT, cache, small_nlp  # noqa: F401 (cache: a fixture)


@pytest.fixture
def no_locks(monkeypatch):
    def flock(fd, operation):
        if operation & fcntl.LOCK_UN:
            return None
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))

    monkeypatch.setattr(fcntl, "flock", flock)


def test_a_compile_cache_that_cannot_lock_is_one_line_naming_the_setting(cache, no_locks):  # noqa: F811
    with pytest.raises(compile_cache.CacheLocationError) as raised:
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    message = str(raised.value)
    assert message.startswith(f"${compile_cache.CACHE_ENV}={cache.parent}: cannot lock {cache}/")
    assert message.endswith(
        ".lock (No locks available): its file system does not lock files; set $CROWDMPC_CACHE to a folder on "
        "a file system that does"
    )
    assert not [p for p in cache.iterdir() if p.suffix != ".lock"]  # nothing compiled, nothing stored


@pytest.mark.parametrize(
    "unless", [lambda p: cache_entries.unless_locked(p), lambda p: locking.unless_held(p, gone=True)]
)
def test_a_writers_lock_that_cannot_be_asked_counts_as_held(tmp_path, no_locks, unless):
    """What the lock guards (a compile under way, a running calibrate's journal, a sweep's scratch) is kept:
    removing it under a live writer would lose its work, keeping a finished one's costs a folder."""
    lock = tmp_path / "x.lock"
    lock.write_text("")
    with unless(lock) as free:
        assert free is False


def test_calibrates_journal_that_cannot_lock_is_one_line_and_leaves_nothing(tmp_path, no_locks):
    from pipelines.commands.calibrate_store import _write_journal

    path = tmp_path / "zoo" / "calibrations.json"
    with pytest.raises(PipelineError) as raised:
        _write_journal(path, [], None)
    assert "cannot lock calibrate's journal (No locks available: its file system does not lock files" in str(
        raised.value
    )
    assert str(raised.value).endswith("set $CROWDMPC_ZOO to a folder on one that does")
    assert list(Path(path.parent).iterdir()) == []


def test_a_lock_whose_path_never_names_the_file_open_is_held_after_a_few_retakes(tmp_path, monkeypatch):
    """A lock retaken while its path names another file (a failed run removed it) looped for ever on a file
    system whose stat and fstat disagree on a file's identity (some overlay mounts' inode numbers)."""
    from predictors import locking
    from tests.waits import within

    opened = []
    real_open = locking._open_lock
    monkeypatch.setattr(locking, "_names", lambda path, fd: False)
    monkeypatch.setattr(
        locking, "_open_lock", lambda path, purpose: opened.append(1) or real_open(path, purpose)
    )
    ran = []
    with within(10, "locked() retaking a lock for ever"), locking.locked(tmp_path / ".lock", "test"):
        ran.append(1)
    assert ran == [1]
    assert len(opened) == locking._RETAKES + 1
