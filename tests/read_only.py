"""A directory this process cannot create anything in, and a file size limit, for tests of outputs that cannot
be written."""

from __future__ import annotations

import contextlib
import os
import resource
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest


@pytest.fixture
def read_only_place(tmp_path: Path) -> Iterator[Path]:
    """A folder made read-only (mode 0o555); as root, who writes there anyway, /sys (sysfs refuses mkdir)."""
    folder = tmp_path / "read_only"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        if not os.access(folder, os.W_OK):
            yield folder
            return
        probe = Path("/sys") / "crowdmpc-write-probe"
        try:
            probe.mkdir()
        except OSError:
            yield Path("/sys")
            return
        with contextlib.suppress(OSError):
            probe.rmdir()
        pytest.skip("no read-only place here (root, and /sys accepts mkdir)")
    finally:
        folder.chmod(0o755)  # for pytest's clean-up


@contextlib.contextmanager
def file_size_limit(size: int) -> Iterator[None]:
    """Writes past ``size`` bytes of any file fail with EFBIG (``ulimit -f``, as a full disk fails them);
    Python ignores the SIGXFSZ that would otherwise end the process."""
    assert signal.getsignal(signal.SIGXFSZ) == signal.SIG_IGN
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (size, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
