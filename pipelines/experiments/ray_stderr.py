"""Ray's C++ log lines said once while a sweep joins a cluster (pipelines.experiments.ray_join).

A cluster that refuses the driver's authentication token is retried by Ray's client once a second for 20 s,
and each refusal is a C++ warning on the process's stderr ("Failed to get cluster ID from GCS server:
Unauthenticated: ... InvalidAuthToken ..."): twenty lines alike before the sweep's one line that says the
same. No logging setting of Ray reaches them (Ray 2.60: RAY_BACKEND_LOG_LEVEL=error, set before ray.init or
even before Python starts, left all twenty; ``ray.init(logging_level=...)`` sets Python's logger only), and
silencing Ray's C++ log outright would hide what a join that is slow for another reason says. So for the
join alone, file descriptor 2 is a pipe whose lines a thread copies to the real stderr as they come,
dropping a C++ line whose text (after its "[time level pid tid]" prefix) was said already in this join:
every distinct line still shows, at once and in order.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import threading
from collections.abc import Iterator
from typing import Final

# Ray's C++ lines: "[2026-12-07 23:38:53,263 W 28117 28117] gcs_client.cc:210: Failed to ..."
RAY_CPP_LINE: Final = re.compile(rb"^\[\d{4}-\d\d-\d\d [^\]]*\] ")
# the copier's last lines, once the join is over (a process Ray left holds the pipe)
DRAIN_S: Final[float] = 2.0


@contextlib.contextmanager
def repeats_said_once() -> Iterator[None]:
    """Within the block, a Ray C++ line on stderr that repeats one said already in the block is dropped;
    everything else passes as it comes. Where stderr has no file descriptor, nothing changes."""
    with contextlib.suppress(AttributeError, ValueError, OSError):  # sys.stderr None, closed or no file
        sys.stderr.flush()
    try:
        real = os.dup(2)
    except OSError:  # no file descriptor 2 to stand in for
        yield
        return
    read, write = os.pipe()
    os.dup2(write, 2)
    os.close(write)
    copier = threading.Thread(target=_copy_new_lines, args=(read, real), name="ray-stderr", daemon=True)
    copier.start()
    try:
        yield
    finally:
        with contextlib.suppress(AttributeError, ValueError, OSError):
            sys.stderr.flush()
        os.dup2(real, 2)  # the pipe's last write end here closes: the copier reads to its end
        copier.join(DRAIN_S)
        if not copier.is_alive():  # else it still copies, to ``real``: left open for it
            os.close(real)


def _copy_new_lines(read: int, real: int) -> None:
    said: set[bytes] = set()
    with os.fdopen(read, "rb") as pipe:
        for line in pipe:
            ray_line = RAY_CPP_LINE.match(line)
            if ray_line is not None:
                text = line[ray_line.end() :]
                if text in said:
                    continue
                said.add(text)
            _write_all(real, line)


def _write_all(fd: int, data: bytes) -> None:
    """``data`` to ``fd``; a stderr that is gone drops it, so the copier keeps draining the pipe (a full pipe
    would stop every writer to stderr, the driver's included)."""
    with contextlib.suppress(OSError):
        while data:
            data = data[os.write(fd, data) :]
