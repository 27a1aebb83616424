"""A compile whose process is killed by SIGKILL (no handler, no ``finally``): on Linux gcc ends with the
process (mpc.compiler.ends_with_this_process), on the main thread and off it, and the cache stays usable."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from mpc import compile_cache, compiler
from mpc.cache_entries import LEFTOVER_AGE_S
from tests.mpc.test_compile_cache import IPOPT, ROOT, fake_compiler, needs_gcc, small_nlp, suffixes

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")

KILLED = """
import sys, threading
sys.path.insert(0, {root!r})
from mpc import compile_cache
from tests.mpc.test_compile_cache import IPOPT, small_nlp
compile_cache.compiler = lambda: compile_cache.Compiler({gcc!r}, "x", ("-O2",))
def compile():
    compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
if {threaded!r}:  # DMPC's helper threads build their robots' IPOPT
    thread = threading.Thread(target=compile)
    thread.start()
    thread.join()
else:
    compile()
"""


def running(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, gone but not reaped by whoever inherited it, does not)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii")
    except FileNotFoundError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] not in ("Z", "X")


@pytest.fixture
def cache(tmp_path: Path) -> Path:
    return tmp_path / "cache" / compile_cache.SUBDIR


@pytest.mark.parametrize("threaded", [False, True], ids=["main-thread", "helper-thread"])
def test_a_sigkill_of_the_compiling_process_ends_gcc(cache, tmp_path, threaded):
    """gcc (a stand-in here that writes its output after 3 s) ran on after a SIGKILL of its process, for
    the seconds of its compile, and wrote its object file into the cache. Now it ends with the process."""
    gcc_pid, started = tmp_path / "gcc.pid", tmp_path / "started"
    out = 'for a; do [ "$o" = 1 ] && out=$a; o=; [ "$a" = -o ] && o=1; done'
    body = f'{out}; echo $$ > {gcc_pid}.new; mv {gcc_pid}.new {gcc_pid}; : > {started}; sleep 3; : > "$out"'
    script = tmp_path / "child.py"
    slow = fake_compiler(tmp_path, body)
    script.write_text(textwrap.dedent(KILLED.format(root=str(ROOT), gcc=slow.path, threaded=threaded)))
    env = os.environ | {compile_cache.CACHE_ENV: str(cache.parent)}
    child = subprocess.Popen([sys.executable, str(script)], env=env, start_new_session=True)
    pid = None
    try:
        for _ in range(2400):  # up to 2 min to reach the compile on a loaded host
            if started.exists() or child.poll() is not None:
                break
            time.sleep(0.05)
        pid = int(gcc_pid.read_text())
        assert running(pid)
        child.kill()
        assert child.wait(timeout=10) == -signal.SIGKILL
        deadline = time.monotonic() + 2
        while running(pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not running(pid), "gcc ran on after its process was killed"
        time.sleep(3.5)  # a gcc that outlived its process would write its object file by now
        assert ".o" not in suffixes(cache)
    finally:
        for group in (child.pid, pid):
            if group is not None:  # before the change: the sleeping stand-in, still there
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(group, signal.SIGKILL)
        child.wait()


@needs_gcc
def test_the_cache_after_a_killed_compile_compiles_and_removes_its_files(cache, tmp_path, monkeypatch):
    """What a SIGKILLed compile leaves (its generated source) goes with the hour-old leftovers, and a
    compile after it makes a working entry."""
    started = tmp_path / "started"
    slow = fake_compiler(tmp_path, f": > {started}; exec sleep 60")
    script = tmp_path / "child.py"
    script.write_text(textwrap.dedent(KILLED.format(root=str(ROOT), gcc=slow.path, threaded=False)))
    env = os.environ | {compile_cache.CACHE_ENV: str(cache.parent)}
    child = subprocess.Popen([sys.executable, str(script)], env=env, start_new_session=True)
    try:
        for _ in range(2400):
            if started.exists() or child.poll() is not None:
                break
            time.sleep(0.05)
        child.kill()
        child.wait(timeout=10)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(child.pid, signal.SIGKILL)
    left = [p for p in cache.iterdir() if p.suffix != ".lock"]
    assert [p.suffix for p in left] == [".c"]
    for path in left:  # killed more than LEFTOVER_AGE_S ago
        os.utime(path, (time.time() - 2 * LEFTOVER_AGE_S,) * 2)
    monkeypatch.setenv(compile_cache.CACHE_ENV, str(cache.parent))
    monkeypatch.chdir(tmp_path)
    solver = compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    assert solver(x0=0, p=[1, 2], lbg=-1, ubg=1)["x"].shape == (2, 1)
    assert suffixes(cache) == [".casadi", ".record", ".so"]


def test_gcc_is_not_ended_when_the_thread_that_started_it_is_done_starting_it():
    """The parent-death signal comes when the thread that forked the child ends: had the thread that
    starts gcc ended once Popen returned, every compile would have ended there."""
    compiler.run_compiler(["/bin/sh", "-c", "sleep 0.5"], "Compilation", lambda: None)


def test_a_child_whose_parent_is_gone_before_it_asked_exits_instead_of_running_on():
    """Killed between fork and prctl, the parent sends no signal: the child sees another parent and exits."""
    orphaned = compiler.ends_with_this_process(parent=1)  # a parent it does not have: its own is gone
    assert subprocess.run(["/bin/sh", "-c", "exit 0"], preexec_fn=orphaned, check=False).returncode == 1
    ours = compiler.ends_with_this_process()
    assert subprocess.run(["/bin/sh", "-c", "exit 0"], preexec_fn=ours, check=False).returncode == 0


def test_a_handler_that_holds_the_signal_is_asked_before_the_compile_stops():
    """A sweep's pool worker holds a SIGTERM sent to the sweep's process group while its episode runs
    (pipelines.experiments.pool_stop): the episode's compile goes on while the handler holds it, and stops,
    its files removed, at the one it does not hold; ended_after_cleanup took over the default action
    alone."""
    from mpc.compiler import ended_after_cleanup

    held: list[int] = []
    ended: list[int] = []  # where the worker's handler would end the process (the default action)

    def holds(signum: int) -> bool:  # the first only
        if held:
            return False
        held.append(signum)
        return True

    def worker_handler(signum, frame):
        if not holds(signum):
            ended.append(signum)

    worker_handler.holds = holds
    previous = signal.signal(signal.SIGTERM, worker_handler)
    try:
        with pytest.raises(BaseException) as stopped, ended_after_cleanup() as check:
            signal.raise_signal(signal.SIGTERM)
            check()  # held: the compile goes on
            assert held == [signal.SIGTERM]
            signal.raise_signal(signal.SIGTERM)
            check()
        assert type(stopped.value).__name__ == "_Ended"  # unwound to the compile's clean-up
        assert ended == [signal.SIGTERM]  # and then ended as it was told to
    finally:
        signal.signal(signal.SIGTERM, previous)
