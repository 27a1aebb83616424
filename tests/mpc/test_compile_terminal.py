"""A cold compile on a terminal: gcc runs in a process group of its own (mpc.compiler.run_compiler), a
background group of the terminal, where a write is stopped by SIGTTOU when the terminal has `stty tostop`."""

from __future__ import annotations

import contextlib
import os
import pty
import select
import shutil
import signal
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

CHILD = """
import sys, termios
sys.path.insert(0, {root!r})
attrs = termios.tcgetattr(0)
attrs[3] |= termios.TOSTOP  # `stty tostop`: a background group's write to the terminal stops it
termios.tcsetattr(0, termios.TCSANOW, attrs)
from mpc import compile_cache
from tests.mpc.test_compile_cache import IPOPT, small_nlp
compile_cache.compiler = lambda: compile_cache.Compiler({gcc!r}, "x", ("-O2",))
compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
print("compiled", flush=True)
"""


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")
def test_a_compiler_warning_on_a_tostop_terminal_is_shown_and_the_compile_ends(tmp_path):
    """gcc's messages went to the terminal itself: under `stty tostop` its first warning stopped it (SIGTTOU
    to a background group) and the compile waited for ever. They now reach the terminal through our stderr,
    written by the foreground process once gcc has ended."""
    gcc = tmp_path / "gcc"
    gcc.write_text(
        f'#!/bin/sh\necho "crowdmpc-test: a warning of gcc" >&2\nexec {shutil.which("gcc")} "$@"\n'
    )
    gcc.chmod(0o755)
    script = tmp_path / "child.py"
    script.write_text(CHILD.format(root=str(ROOT), gcc=str(gcc)))
    env = os.environ | {"CROWDMPC_CACHE": str(tmp_path / "cache")}
    pid, fd = pty.fork()
    if pid == 0:  # the child: a session of its own, the pty its terminal, itself the foreground group
        os.chdir(tmp_path)
        os.execve(sys.executable, [sys.executable, str(script)], env)
    out, reaped = b"", False
    deadline = time.monotonic() + 180  # a cold compile of the small NLP takes seconds; 3 min under load
    try:
        while not reaped and time.monotonic() < deadline:
            if select.select([fd], [], [], 1.0)[0]:
                try:
                    out += os.read(fd, 4096)
                except OSError:  # EIO: the child closed the terminal
                    pass
            reaped = os.waitpid(pid, os.WNOHANG)[0] == pid
    finally:
        if not reaped:  # stopped for ever (the fault) or still compiling: end it
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        with contextlib.suppress(OSError):
            while select.select([fd], [], [], 0.2)[0] and (chunk := os.read(fd, 4096)):
                out += chunk  # what it wrote last
        os.close(fd)
    assert reaped, f"the compile did not end within 3 min: {out.decode(errors='replace')}"
    text = out.decode(errors="replace")
    assert "crowdmpc-test: a warning of gcc" in text and "compiled" in text, text
