"""How the process pool's workers (pipelines.experiments.process_backend) start: each spawned process
copies the driver's environment and signal dispositions at its start, so the driver sets them for the
milliseconds a spawn takes."""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Iterator


@contextlib.contextmanager
def child_environment(values: dict[str, str]) -> Iterator[None]:
    """Environment for processes started inside the block (spawned workers copy it at start)."""
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextlib.contextmanager
def children_ignore_sigint() -> Iterator[None]:
    """Processes started inside the block ignore SIGINT from their first instruction (an ignored signal
    stays ignored across exec): a Ctrl-C while a worker still imports (seconds, before its initializer
    ignores it) printed that worker's KeyboardInterrupt traceback under the driver's "interrupted" line.
    The driver ignores it too for the milliseconds a spawn takes; only the main thread may set handlers."""
    import signal

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
