"""Multiprocessing's resource tracker, as the process pool's backend starts it: quiet about a killed driver's
semaphores, and alive through a closed terminal's SIGHUP."""

from __future__ import annotations

import os
import signal


def start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker (unless it runs already) so that it does not warn about the
    pool's semaphores when the driver is killed.

    The pool's queues hold named POSIX semaphores (5; spawn needs names the workers can open), which the
    driver registers with the tracker, a process of its own, and unregisters when it exits. A driver killed by
    SIGKILL cannot; the tracker then unlinks them, which is what it is for, and warns "There appear to be 5
    leaked semaphore objects to clean up at shutdown" on the terminal after the driver is gone. Nothing is
    left behind, so that warning is noise: the tracker starts with it filtered out (its warning filters come
    from the environment it starts in). SIGTERM and SIGHUP end a sweep in an orderly way (run_sweep), with no
    warning either. The tracker starts with SIGHUP blocked (a blocked signal stays blocked across exec): it
    ignores SIGINT and SIGTERM only, so a closed terminal, which signals every process of the job, killed it,
    and the sweep's orderly stop then warned that it relaunched it and printed a traceback per semaphore."""
    from multiprocessing import resource_tracker

    quiet = "ignore:resource_tracker:UserWarning"
    saved = os.environ.get("PYTHONWARNINGS")
    os.environ["PYTHONWARNINGS"] = f"{saved},{quiet}" if saved else quiet
    # the driver's own SIGHUP, if one comes meanwhile, is held and delivered when its mask is restored
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, [signal.SIGHUP]) if hasattr(signal, "SIGHUP") else None
    try:
        resource_tracker.ensure_running()
    finally:
        if mask is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        if saved is None:
            os.environ.pop("PYTHONWARNINGS", None)
        else:
            os.environ["PYTHONWARNINGS"] = saved
