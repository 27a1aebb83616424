"""The compile cache's lock files when users share the cache (a lab's `CROWDMPC_CACHE` under umask 002): a
second user's compile stopped with "Permission denied" on the lock file the first one had made 0644, where
it should wait for that compile and use its entry."""

from __future__ import annotations

import os
import stat
import threading

from mpc import cache_entries
from mpc.cache_entries import locked, unless_locked


def test_a_lock_file_takes_the_permissions_the_umask_leaves(tmp_path):
    previous = os.umask(0o002)
    try:
        with locked(tmp_path / "entry.lock"):
            pass
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / "entry.lock").stat().st_mode) == 0o664  # the group's too


def _refused(monkeypatch, *, read_too: bool = False) -> None:
    """os.open refusing to open for writing (another user's 0644 file), and to read too with ``read_too``:
    root, who runs CI's containers, is refused nothing by the permissions themselves."""
    real = os.open

    def open_as_another_user(path, flags, *mode):
        if flags & os.O_RDWR or read_too:
            raise PermissionError(13, "Permission denied", str(path))
        return real(path, flags, *mode)

    monkeypatch.setattr(cache_entries.os, "open", open_as_another_user)


def test_another_users_lock_is_held_through_a_descriptor_opened_to_read(tmp_path, monkeypatch):
    lock = tmp_path / "entry.lock"
    lock.touch()
    _refused(monkeypatch)
    order = []

    def second() -> None:
        with locked(lock):
            order.append("second")

    with locked(lock):
        waiter = threading.Thread(target=second)
        waiter.start()
        waiter.join(0.3)
        order.append("first released")  # the second waited for the first, as between two users' compiles
    waiter.join(5)
    assert order == ["first released", "second"]
    with unless_locked(lock) as free:
        assert free


def test_a_lock_this_user_may_not_read_counts_as_held(tmp_path, monkeypatch):
    """cache clear asks unless_locked before removing an entry's files: a lock it could not open counted as
    nobody's, so another user's compile under way lost its files."""
    lock = tmp_path / "entry.lock"
    lock.touch()
    _refused(monkeypatch, read_too=True)
    with unless_locked(lock) as free:
        assert not free
