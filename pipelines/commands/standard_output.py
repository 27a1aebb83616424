"""``--json -``: a command's JSON document on standard output, the Unix convention, with everything else the
command prints (tables, notes, progress) sent to standard error for that run, so that ``crowdmpc simulate
... --json - | jq .`` reads one document and nothing else. Shared by every command and benchmark script
with a ``--json`` option, and by a config file's ``json = "-"``."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Final, TextIO

from pipelines.commands.output_paths import check_names_a_file, without_missing_parents
from pipelines.errors import PipelineError

# The one value that names standard output. Told apart by identity, not equality: Path("./-") == Path("-"),
# and "./-" is how a user names a file called "-" (as with cat, tar and every tool that reads "-").
STDOUT: Final[Path] = Path("-")
STDOUT_TEXT: Final[str] = "-"

# Where the document goes while a run sends it to standard output: the saved descriptor of the real
# standard output (fd 1 itself then points at stderr), or the stream when it has no descriptor (captured).
_document: int | TextIO | None = None


def json_path(text: str) -> Path:
    """An option's ``--json`` value (or a config file's): ``STDOUT`` for "-", else the path
    (``without_missing_parents``)."""
    if text == STDOUT_TEXT:
        return STDOUT
    if not text:
        import argparse

        raise argparse.ArgumentTypeError("must be a path or -, got ''")
    check_names_a_file(text)
    return without_missing_parents(Path(text))


def is_stdout(path: object) -> bool:
    """Whether ``path`` is ``STDOUT`` (an option's "-"), not a file."""
    return path is STDOUT


def shown(path: Path) -> str:
    """``path`` as a message names it: a file called "-" in the working directory as "./-", since
    ``Path("./-")`` prints as "-", which reads as standard output ("wrote -" after ``--json ./-``)."""
    text = str(path)
    return "./-" if text == STDOUT_TEXT else text


@contextlib.contextmanager
def json_on_stdout(path: Path | None) -> Iterator[None]:
    """Around a run whose JSON output is ``path``: when that is ``STDOUT``, whatever else the run prints goes
    to standard error, Python's prints and also what C libraries and child processes write on descriptor 1,
    until the run ends; ``write_document`` writes on the real standard output meanwhile. Else nothing
    changes."""
    global _document
    if not is_stdout(path):
        yield
        return
    stream = sys.stdout
    if stream is None:  # started with descriptor 1 closed (`>&-`): Python then has no sys.stdout
        raise PipelineError("--json -: standard output is closed; name a file instead")
    stream.flush()
    saved = _divert_descriptor(stream)
    _document = stream if saved is None else saved
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        _document = None
        if saved is not None:
            os.dup2(saved, stream.fileno())
            os.close(saved)


def _divert_descriptor(stream: TextIO) -> int | None:
    """Point ``stream``'s descriptor at stderr's, returning a copy of what it was; None where either has no
    descriptor (a test's captured output), which leaves Python's own prints as the only ones diverted."""
    try:
        out, err = stream.fileno(), sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):
        return None
    saved = os.dup(out)
    os.dup2(err, out)
    return saved


def write_document(text: str, option: str) -> None:
    """``text`` on the run's real standard output. A reader that left is the caller's BrokenPipeError (the
    CLI ends quietly on it); any other failure (``> /dev/full``) is a one-line PipelineError naming
    ``option``."""
    target: int | TextIO | None = sys.stdout if _document is None else _document
    if target is None:  # started with descriptor 1 closed, a command without json_on_stdout (cache info)
        raise PipelineError(f"{option} -: standard output is closed; name a file instead")
    try:
        if isinstance(target, int):
            # written straight to the descriptor: a failed buffered write would be flushed, and fail,
            # once more at exit, with a traceback-like "Exception ignored" message
            data = memoryview(text.encode())
            while data:
                data = data[os.write(target, data) :]
        else:
            target.write(text)
            target.flush()
    except BrokenPipeError:
        raise
    except OSError as exc:
        raise PipelineError(
            f"{option} -: could not write to standard output ({exc.strerror or exc})"
        ) from None


def hold_standard_descriptors() -> None:
    """For a program started with a standard descriptor closed (``>&-``, ``2>&-``): /dev/null on it, as a
    daemon does, so that no file the run opens takes its number (with ``2>&-`` the MCAP log was descriptor 2,
    and whatever a C library or child process writes on stderr went into the log), and a sys.stderr that can
    be written when Python had none (a progress bar wrote to None and ended the run with status 1).
    sys.stdout stays None: ``--json -`` then refuses in one line (``json_on_stdout``, ``write_document``)."""
    for fd in (0, 1, 2):  # in order: os.open takes the lowest free number, so each lands on its own
        try:
            os.fstat(fd)
        except OSError:
            null = os.open(os.devnull, os.O_RDWR)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
    if sys.stderr is None:
        # the process's own stream, never closed (SIM115 does not apply)
        sys.stderr = open(2, "w", encoding="utf-8", closefd=False, errors="backslashreplace")  # noqa: SIM115
