"""The C compiler CasADi's jit calls: which one (gcc on the PATH, as the compile cache's key records it) and
the shell command CasADi runs it with."""

from __future__ import annotations

import contextlib
import shlex
import shutil
import signal
import subprocess
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Final

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


def interruptible(compiler: str, marker: Path) -> str:
    """The shell command CasADi runs as the compiler and linker: ``compiler`` with the arguments CasADi
    appends, leaving ``marker`` when a SIGINT stopped it. CasADi runs it with ``system()``, which ignores
    SIGINT in our process while it waits, so a Ctrl-C during a cold compile reached only gcc and came back
    as "Compilation failed"; the marker lets ``compile_cache`` raise KeyboardInterrupt instead. The
    shell's trap (not an ignore, which gcc would inherit) runs once gcc has ended; 130 is a child ended by
    SIGINT."""
    script = (
        f'trap "stopped=1" INT; "$0" "$@"; status=$?; '
        f'if [ "$status" -eq 130 ] || [ -n "$stopped" ]; then : > {shlex.quote(str(marker))}; fi; '
        f'exit "$status"'
    )
    return f"/bin/sh -c {shlex.quote(script)} {shlex.quote(compiler)}"


# ended_after_cleanup's check: raises where a compile can stop when an ending signal was noted
Check = Callable[[], None]


class _Ended(BaseException):
    """A signal ``ended_after_cleanup`` noted: unwinds the compile to its clean-up (never caught)."""


@contextlib.contextmanager
def ended_after_cleanup() -> Iterator[Check]:
    """Around a compile: a SIGTERM or SIGHUP whose action is the default (the process ends, no ``finally``
    run) is noted instead, and ends the process as it would have once the block is left, its clean-up done:
    a worker a sweep's stop ended while gcc ran left the generated source (~0.5 MB) and object file in the
    cache, and gcc, running on, wrote them after its parent had gone. The yielded check raises where the
    compile can stop (after gcc: a signal reaches Python only once CasADi's ``system()`` returns). Another
    handler (the CLI's terminate_as_interrupt, a program's) or an ignored signal is left as it is, and so is
    every signal off the main thread, which may set no handler."""
    noted: list[int] = []

    def check() -> None:
        if noted:
            raise _Ended(noted[0])

    if threading.current_thread() is not threading.main_thread():
        yield check
        return
    ending = [s for s in ENDING if signal.getsignal(s) is signal.SIG_DFL]
    saved = {s: signal.signal(s, lambda signum, frame: noted.append(signum)) for s in ending}
    try:
        yield check
    finally:
        for s, handler in saved.items():
            signal.signal(s, handler)
        if noted:  # the default action again, now: the process ends as it was told to (143 for SIGTERM)
            signal.raise_signal(noted[0])
