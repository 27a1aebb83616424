"""DMPC's local solves in threads (mpc/parallel.py): results in the jobs' order, and no job started after one
raised."""

import threading
import time
import types
from concurrent.futures import ThreadPoolExecutor

import pytest

from mpc import parallel
from mpc.parallel import run_in_threads

HELPERS = 2


def test_every_job_runs_once_and_the_results_come_in_the_jobs_order():
    ran = []

    def run(k, scale):
        ran.append(k)
        time.sleep(0.001)
        return k * scale

    with ThreadPoolExecutor(HELPERS) as pool:
        assert run_in_threads(pool, HELPERS, run, [(k, 10) for k in range(30)]) == [10 * k for k in range(30)]
    assert sorted(ran) == list(range(30))


@pytest.mark.parametrize("where", ["caller", "helper"])
def test_no_job_starts_after_one_raised(where):
    """Jobs of 5 ms (a local solve's time, in sleep, which releases the GIL as a solver call does); the
    first job the calling thread takes raises KeyboardInterrupt (Ctrl-C), or the first one a helper takes
    a RuntimeError. The other threads finish the job they are in, and start at most one more each (taken
    just before the raise), where they drained all 60 before."""
    log: list[str | int] = []
    raised = threading.Event()

    def run(k):
        in_caller = threading.current_thread() is threading.main_thread()
        if in_caller == (where == "caller") and not raised.is_set():
            raised.set()
            log.append("raised")
            raise KeyboardInterrupt if in_caller else RuntimeError("solver failed")
        log.append(k)
        time.sleep(0.005)
        return k

    expected = KeyboardInterrupt if where == "caller" else RuntimeError
    with ThreadPoolExecutor(HELPERS) as pool, pytest.raises(expected):
        run_in_threads(pool, HELPERS, run, [(k,) for k in range(60)])
    after = log[log.index("raised") + 1 :]
    assert len(after) <= HELPERS, f"{len(after)} jobs started after one raised"


def test_a_job_a_helper_took_is_run_even_as_the_caller_ends(monkeypatch):
    """The caller sets the stop once its own drain ends; a helper that took the last job just before must
    still run it (it read the stop between taking a job and running it, and left that job's result None).
    The helper's read of the stop is made to wait for the caller's set, the worst order of the two."""

    class LateEvent(threading.Event):
        def is_set(self) -> bool:
            if threading.current_thread() is not threading.main_thread():
                self.wait(2.0)  # a helper reads the stop only after the caller has set it
            return super().is_set()

    monkeypatch.setattr(parallel, "threading", types.SimpleNamespace(Event=LateEvent))
    with ThreadPoolExecutor(2) as pool:
        assert run_in_threads(pool, 2, lambda x: x + 1, [(k,) for k in range(6)]) == list(range(1, 7))
