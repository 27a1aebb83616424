"""The C compiler of the jit: which one (gcc on the PATH, as the compile cache's key records it), the
commands CasADi would run it with, run here so that a signal stops it at once, and the shell command CasADi
runs in their place."""

from __future__ import annotations

import contextlib
import ctypes
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from types import FrameType
from typing import IO, Any, Final

COMPILER: Final[str] = "gcc"  # CasADi's "shell" compiler plugin calls it
# -ffp-contract=off: the compiled NLP must round as CasADi's interpreter does, so that --jit changes the time
# and not a number (jit on and off were equal on 32 of 32 sweep episodes, x86-64). gcc fuses a * b + c into
# one rounding wherever the target has FMA, by default on aarch64 (and on x86-64 with -march=native).
FLAGS: Final[tuple[str, ...]] = ("-O2", "-ffp-contract=off")
# The signals whose default action ends a process with no ``finally`` run: a sweep's workers get SIGTERM from
# the driver's stop (ProcessBackend._end_pool), a job scheduler's or `kill`'s; a closed terminal sends SIGHUP.
ENDING: Final[tuple[signal.Signals, ...]] = tuple(
    getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name)
)


@dataclass(frozen=True)
class Compiler:
    """The C compiler the jit calls, as the key records it."""

    path: str  # absolute path of gcc
    version: str  # first line of ``gcc --version``
    flags: tuple[str, ...]

    def describe(self) -> str:
        return f"{self.version} ({self.path}) {' '.join(self.flags)}"


@cache
def compiler() -> Compiler | None:
    """gcc on the PATH, or None (then nothing can be compiled). Asked once per process."""
    path = shutil.which(COMPILER)
    if path is None:
        return None
    try:
        out = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=30, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return Compiler(path, (out.stdout.splitlines() or ["unknown"])[0].strip(), FLAGS)


def interruptible(command: str, marker: Path) -> str:
    """The shell command CasADi runs as the compiler and linker: ``command`` with the arguments CasADi
    appends, leaving ``marker`` when a SIGINT stopped it. CasADi runs it with ``system()``, which ignores
    SIGINT in our process while it waits, so a Ctrl-C then would reach only the shell and come back as
    "Compilation failed"; the marker lets ``compile_cache`` raise KeyboardInterrupt instead. The compile
    cache gives ``:`` (gcc has run already, ``run_compiler``): the window is the milliseconds of a shell.
    The shell's trap (not an ignore, which the command would inherit) runs once the command has ended;
    130 is a child ended by SIGINT."""
    script = (
        f'trap "stopped=1" INT; "$0" "$@"; status=$?; '
        f'if [ "$status" -eq 130 ] || [ -n "$stopped" ]; then : > {shlex.quote(str(marker))}; fi; '
        f'exit "$status"'
    )
    return f"/bin/sh -c {shlex.quote(script)} {shlex.quote(command)}"


# What CasADi's "shell" plugin runs on Linux (casadi/solvers/shell_compiler.cpp: compiler, flags, its
# compiler_setup "-fPIC -c", the source, "-o " object; then linker, object, "-o " library, linker_setup
# "-shared"): run_compiler runs gcc with these, so the library is the one CasADi's own compile made.
def compile_command(cc: Compiler, source: str, obj: str) -> list[str]:
    """gcc compiling ``source`` (named as CasADi names it: relative to the cache folder) into ``obj``."""
    return [cc.path, *cc.flags, "-fPIC", "-c", source, "-o", obj]


def link_command(cc: Compiler, obj: str, library: str) -> list[str]:
    """gcc linking ``obj`` into the shared library ``library``."""
    return [cc.path, obj, "-o", library, "-shared"]


# ended_after_cleanup's check: raises where a compile can stop when an ending signal was noted
Check = Callable[[], None]
# How often run_compiler looks for an ending signal noted while gcc runs (ended_after_cleanup's check)
POLL_S: Final[float] = 0.05
# How long gcc's group has to end on SIGTERM (its driver removes its files in /tmp first) before SIGKILL
STOP_S: Final[float] = 5.0


def run_compiler(command: list[str], step: str, check: Check) -> None:
    """Run ``command`` (gcc) in the working directory and wait for it in Python, not in a ``system()`` as
    CasADi's own compile did: that ignored SIGINT in our process (a `kill -INT` of it alone was lost) and
    held every signal's handler until gcc returned, 8 s for CMPC's NLP. On the main thread gcc runs in a
    process group of its own, so that its whole group (cc1, as, ld) is stopped when the compile is: by a
    KeyboardInterrupt, or ``check`` raising for an ending signal (polled every POLL_S); off it, in the
    caller's group, which a terminal's Ctrl-C reaches. On Linux gcc also ends when this process does, by a
    SIGKILL too (ends_with_this_process). RuntimeError when gcc fails, in CasADi's words (``step``:
    "Compilation" or "Linking"); KeyboardInterrupt when a SIGINT ended gcc itself."""
    # Off the main thread no signal reaches this code (Python runs handlers in the main thread alone): gcc
    # stays in the caller's process group there, so that a terminal's Ctrl-C reaches it as before, ends it
    # and comes back as a KeyboardInterrupt; in a group of its own it ran on after its process had exited.
    own_group = threading.current_thread() is threading.main_thread()
    # gcc's messages go to a file and then to our stderr: a group of its own is a background group of the
    # terminal, and under `stty tostop` its first warning written there stopped it (SIGTTOU), the compile
    # waiting for ever (tests/mpc/test_compile_terminal.py); a pipe could fill while nobody reads it
    with tempfile.TemporaryFile() as output:
        spawn = _Spawn(command, own_group, output)
        try:
            spawn.start()
            spawn.wait_started()
            started = spawn.started
            if not isinstance(started, subprocess.Popen):  # gcc gone since it was found: the shell's 127 was
                raise RuntimeError(f'{step} failed. Tried "{shlex.join(command)}": {started}')  # failed
            status = _wait(started, check)
        finally:
            process = spawn.cancel()
            try:  # stopped while gcc runs: its group goes
                if process is not None and process.returncode is None:
                    _stop_group(process, own_group)
            finally:
                spawn.finish()
        _pass_on(output)
    if status in (-signal.SIGINT, 130):
        raise KeyboardInterrupt
    if status != 0:
        raise RuntimeError(f'{step} failed. Tried "{shlex.join(command)}"')


# prctl(2)'s option: the signal a process gets when the thread that forked it ends (Linux; <sys/prctl.h>)
PR_SET_PDEATHSIG: Final[int] = 1


@cache
def _prctl() -> Callable[..., int] | None:
    """libc's prctl, resolved here and not in the forked child (no dlopen between fork and exec); None off
    Linux, where gcc keeps today's behaviour: a SIGKILL of this process leaves it to finish."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]
    prctl.restype = ctypes.c_int
    return prctl


def ends_with_this_process(parent: int | None = None) -> Callable[[], None] | None:
    """What the forked child runs before it execs gcc, so that gcc ends with this process, a SIGKILL of it
    included (no handler, no ``finally`` runs: gcc ran on for seconds and wrote its object file into the
    cache); None where prctl is not there. The signal is SIGTERM, on which gcc's driver removes its
    temporary files (a SIGKILL left cc1's assembly in /tmp: 0.6 MB for CMPC's NLP, 2 robots, 3 humans), or
    SIGKILL where this process ignores SIGTERM, as gcc then would. The driver's children (cc1, as, ld) are
    not signalled: one running goes on to its end (cc1: seconds, into the deleted file), and none starts
    after. The thread that forks gcc must outlive it (_Spawn): the signal comes when it ends. A parent gone
    when the child asks (killed between fork and prctl) is not waited for: the child exits. ``parent``:
    the process the child expects to be forked by (default: this one)."""
    prctl = _prctl()
    if prctl is None:
        return None
    parent = os.getpid() if parent is None else parent
    ignored = signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
    death = int(signal.SIGKILL if ignored else signal.SIGTERM)

    def in_the_child() -> None:  # between fork and exec: no imports, no allocation beyond the call
        prctl(PR_SET_PDEATHSIG, death, 0, 0, 0)
        if os.getppid() != parent:  # orphaned before the prctl took effect: no signal will come
            os._exit(1)

    return in_the_child


class _Spawn(threading.Thread):
    """Starts ``command`` (in a process group of its own: ``own_group``) in a thread of its own: a
    KeyboardInterrupt raised in the main thread inside Popen (gcc running, Popen waiting to learn that its
    exec worked) lost the Popen, and gcc ran on (a Ctrl-C test's stand-in outlived its program). ``cancel``
    returns the process, if any: none starts after it. The thread lives on until ``finish``: on Linux
    gcc's parent-death signal comes when the thread that forked it ends (ends_with_this_process)."""

    def __init__(self, command: list[str], own_group: bool, output: IO[bytes]) -> None:
        super().__init__(name="crowdmpc-gcc", daemon=True)
        self.command = command
        self.own_group = own_group
        self.output = output  # gcc's standard output and error
        self.started: subprocess.Popen | OSError | None = None
        self._lock = threading.Lock()  # held while Popen runs
        self._cancelled = False
        self._tried = threading.Event()  # set once Popen has returned or raised (or was cancelled)
        self._done = threading.Event()  # set once gcc is reaped: the thread may end

    def run(self) -> None:
        try:
            with self._lock:
                if self._cancelled:
                    return
                self.started = subprocess.Popen(
                    self.command,
                    stdin=subprocess.DEVNULL,
                    stdout=self.output,
                    stderr=subprocess.STDOUT,
                    process_group=0 if self.own_group else None,
                    preexec_fn=ends_with_this_process(),
                )
        except OSError as exc:
            self.started = exc
        finally:
            self._tried.set()
        if isinstance(self.started, subprocess.Popen):
            self._done.wait()

    def wait_started(self) -> None:
        """Until Popen has returned (gcc running) or failed."""
        self._tried.wait()

    def cancel(self) -> subprocess.Popen | None:
        with self._lock:  # a Popen under way ends first
            self._cancelled = True
        return self.started if isinstance(self.started, subprocess.Popen) else None

    def finish(self) -> None:
        """Let the thread end: gcc is reaped, or is to end with it."""
        self._done.set()


def _wait(process: subprocess.Popen, check: Check) -> int:
    """``process``'s exit status; ``check`` is called every POLL_S until then (a SIGINT's KeyboardInterrupt
    is raised at once: a signal interrupts the wait, and Python's handler runs)."""
    while True:
        try:
            return process.wait(timeout=POLL_S)
        except subprocess.TimeoutExpired:
            check()


def _pass_on(output: IO[bytes]) -> None:
    """What gcc printed (its warnings, a failed compile's errors) to our stderr, as when it wrote there."""
    output.seek(0)
    text = output.read().decode("utf-8", "replace")
    if text:
        sys.stderr.write(text)
        sys.stderr.flush()


def _stop_group(process: subprocess.Popen, own_group: bool) -> None:
    """End the process group ``process`` leads (not yet reaped: its id is still the group's), or ``process``
    alone when it shares its caller's group (``own_group`` false), and reap it."""

    def send(signum: int) -> None:
        with contextlib.suppress(ProcessLookupError):
            if own_group:
                os.killpg(process.pid, signum)
            else:
                process.send_signal(signum)

    send(signal.SIGTERM)
    try:
        process.wait(timeout=STOP_S)
    except subprocess.TimeoutExpired:
        send(signal.SIGKILL)
        process.wait()


class _Ended(BaseException):
    """A signal ``ended_after_cleanup`` noted: unwinds the compile to its clean-up (never caught)."""


@contextlib.contextmanager
def ended_after_cleanup() -> Iterator[Check]:
    """Around a compile: a SIGTERM or SIGHUP whose action is the default (the process ends, no ``finally``
    run) is noted instead, and ends the process as it would have once the block is left, its clean-up done:
    a worker a sweep's stop ended while gcc ran left the generated source (~0.5 MB) and object file in the
    cache, and gcc, running on, wrote them after its parent had gone. The yielded check raises where the
    compile can stop (while gcc runs, ``run_compiler``; after CasADi's calls, which hold a signal). A handler
    with a ``holds(signum)`` (a sweep's pool worker's, which holds a process group's SIGTERM while its episode
    runs) is asked first: while it holds the signal the compile goes on. Another handler (the CLI's
    terminate_as_interrupt, a program's) or an ignored signal is left as it is, and so is every signal off
    the main thread, which may set no handler."""
    noted: list[int] = []

    def check() -> None:
        if noted:
            raise _Ended(noted[0])

    if threading.current_thread() is not threading.main_thread():
        yield check
        return

    def note(signum: int, frame: FrameType | None) -> None:
        holds = getattr(saved.get(signum), "holds", None)
        if holds is None or not holds(signum):  # a handler that holds it now: the compile goes on
            noted.append(signum)

    # a handler with ``holds`` ends the process as the default does unless it holds the signal (a sweep's
    # pool worker holds a process group's SIGTERM while its episode runs: pipelines.experiments.pool_stop)
    ending = [s for s in ENDING if (h := signal.getsignal(s)) is signal.SIG_DFL or hasattr(h, "holds")]
    saved: dict[int, Any] = {}
    for signum in ending:
        saved[signum] = signal.signal(signum, note)
    try:
        yield check
    finally:
        for s, handler in saved.items():
            signal.signal(s, handler)
        if noted:  # the default action again, now: the process ends as it was told to (143 for SIGTERM)
            signal.raise_signal(noted[0])
