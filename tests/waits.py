"""A bound on how long a test may wait where the code under test could block for good (a named pipe)."""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator


class Waited(BaseException):
    """Raised by ``within``'s alarm: not an Exception, so no handler under test takes it for its own error."""


@contextlib.contextmanager
def within(seconds: int, what: str) -> Iterator[None]:
    """Fail with ``Waited`` ("``what``") after ``seconds``, rather than hang the suite (main thread only)."""

    def waited(signum: int, frame: object) -> None:
        raise Waited(f"{what} (waited {seconds} s)")

    before = signal.signal(signal.SIGALRM, waited)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, before)
