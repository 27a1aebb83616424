"""The C compiler CasADi's jit calls: which one (gcc on the PATH, as the compile cache's key records it) and
the shell command CasADi runs it with."""

from __future__ import annotations

import shlex
import shutil
import subprocess
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Final

COMPILER: Final[str] = "gcc"  # CasADi's "shell" compiler plugin calls it
# -ffp-contract=off: the compiled NLP must round as CasADi's interpreter does, so that --jit changes the time
# and not a number (jit on and off were equal on 32 of 32 sweep episodes, x86-64). gcc fuses a * b + c into
# one rounding wherever the target has FMA, by default on aarch64 (and on x86-64 with -march=native).
FLAGS: Final[tuple[str, ...]] = ("-O2", "-ffp-contract=off")


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
