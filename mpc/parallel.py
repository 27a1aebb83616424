"""DMPC's local solves in threads: the calling thread and helpers draining one shared list of jobs.

Parallelism (``dmpc_parallel="threads"``). The local solves of one iteration are independent, and CasADi
releases the GIL while a solver runs: two threads calling Fatrop local solvers were both inside the solver
71-80 % of the time (1.5-1.8x). What held the thread pool back was the hand-over, one future per solve: on
batches of 6 local problems recorded at M = 6 (about 0.7 ms a solve), 1.2x, where a CasADi
``map(6, "thread")`` over the bare Fatrop solver reached 1.4-1.8x. That map returns no per-robot solver
statistics (status, iterations), which the Fatrop-to-IPOPT fallback and the acceptance rule need, so the
solves stay separate calls: the calling thread and ``cores - 1`` helpers take them from a shared iterator
(``run_in_threads``, called by ``DMPC._solve_all``). Same batches, alternating with the serial path,
load 0.6-0.9 on the 2 cores: 1.45x
(sequential_accept) and 1.57x (jacobi, 13 % of whose solves fall back to IPOPT), identical to the serial
results bit for bit; in closed loop at M = 6 (load 1.0-1.3) the local-solve phase ran 1.38x and 1.50x
faster. What is left is Python around each solve (~85 us of the 0.7 ms, under the GIL) and the other
processes on the cores: the load average decides the speed-up more than the mechanism. And the solves of a
batch are uneven (a Fatrop failure redone by IPOPT costs several ordinary solves), so even with no overhead
two threads taking them in order would reach only x1.69 at M = 6 and x1.85 at M = 12 (Jacobi;
``benchmarks/dmpc_scaling.py --replay`` prints this bound beside the measured x1.55 and x1.72). With
``cost_scale = 0.01`` Fatrop rarely fails, and the bound is x1.80 / x1.89, the step x1.60 / x1.66.
``"serial"`` is the default because DMPC's long runs are sweeps, whose process workers already occupy every
core; ``"threads"`` is the faster choice for a single run on a machine with a free core.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor, wait
from typing import Any, TypeVar, cast

T = TypeVar("T")


def cores() -> int:
    """The CPUs this process may run on (its affinity mask, e.g. under ``taskset``)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def run_in_threads(
    pool: ThreadPoolExecutor, helpers: int, run: Callable[..., T], jobs: Sequence[tuple[Any, ...]]
) -> list[T]:
    """``run(*job)`` for every job, results in the jobs' order: the calling thread and up to ``helpers``
    threads of ``pool`` take the jobs one by one from a shared iterator until none is left, so no thread
    waits while there is work and a job costs no hand-over (a future per job cost a third of the speed-up).
    Once a job raises, in any thread (Ctrl-C's KeyboardInterrupt comes in the calling one), no thread starts
    another: the jobs running finish (a solver's C call cannot be interrupted), and the exception is raised
    here, after every thread has stopped."""
    results: list[T | None] = [None] * len(jobs)
    pending = iter(range(len(jobs)))  # next() on a range iterator is atomic under the GIL
    stop = threading.Event()

    def drain() -> None:
        try:
            # stop is read before a job is taken, never between: a job taken is run (the caller sets stop
            # once its own drain ends, while a helper may have just taken the last job)
            while not stop.is_set():
                k = next(pending, None)
                if k is None:
                    return
                results[k] = run(*jobs[k])
        except BaseException:
            stop.set()
            raise

    started = [pool.submit(drain) for _ in range(min(helpers, len(jobs) - 1))]
    try:
        drain()
    finally:
        # Also for an interrupt outside a job; after a normal return every job is taken, and this stops none.
        stop.set()
        wait(started)  # never leave a job running in a helper after this call
    for helper in started:
        helper.result()
    return cast(list[T], results)
