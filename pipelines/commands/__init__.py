"""One module per CLI subcommand. Each defines ``register(subparsers)``; heavy imports happen inside ``run``
so that ``crowdmpc --help`` stays fast."""

from __future__ import annotations

import argparse
import errno
import json
import os
import stat
import sys
import tempfile
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Final, TypeVar

from pipelines.commands.standard_output import is_stdout, write_document
from pipelines.commands.zoo_outputs import check_not_in_a_zoo, check_not_zoo_file
from pipelines.commands.zoo_outputs import check_outside_the_zoos as check_outside_the_zoos
from pipelines.errors import PipelineError
from pipelines.whole_files import fill_and_rename, remove_killed_temporaries

T = TypeVar("T")

# The shell's exit status of a process that SIGPIPE ended (128 + 13): what `cmd | head` reports for a C tool.
CLOSED_PIPE_STATUS: Final[int] = 141
# A --json report is far smaller; a larger existing file is data, never replaced (check_writable).
MAX_REPORT_BYTES: Final[int] = 64 * 2**20
# A file name's limit (NAME_MAX, Linux and macOS file systems), and how much longer than an output's name the
# temporary names made beside it are: replace_file's ".NAME.XXXXXXXX.part" (+15 bytes), data prepare's
# ".NAME.prepare-PID.tmp" (+21, a PID has at most 7 digits); data synth's is longer (its own room). One room
# for all (21) refused 236-240-byte names that replace_file writes.
NAME_MAX: Final[int] = 255
REPLACE_FILE_ROOM: Final[int] = 15
PREPARE_ROOM: Final[int] = 21


def examples(*commands: str) -> dict[str, object]:
    """``add_parser`` keywords for a command's ``--help`` that ends with its example command lines, laid out
    as written ("example:" / "examples:", each line indented by two spaces)."""
    heading = "example:" if len(commands) == 1 else "examples:"
    epilog = heading + "\n" + "".join(f"  {command}\n" for command in commands)
    return {"epilog": epilog, "formatter_class": argparse.RawDescriptionHelpFormatter}


def path_arg(text: str) -> Path:
    """An option's path: ``Path("")`` is ".", so an empty value (an unset shell variable) read or wrote the
    current directory."""
    if not text:
        raise argparse.ArgumentTypeError("must be a path, got ''")
    return Path(text)


def check_data_files(option: str, paths: Sequence[Path]) -> None:
    """PipelineError in one line unless every path of ``option`` (train's --train, --val, --test, evaluate's
    --test) names an existing regular file, each once: a file named twice, even as another path to it, counts
    its scenes twice while a record names it once."""
    seen: dict[Path, Path] = {}
    for path in paths:
        if not path.exists():
            raise PipelineError(f"{option} file {path} does not exist")
        if not path.is_file():
            raise PipelineError(f"{option} {path} is not a data file (a directory or a device)")
        again = seen.setdefault(path.resolve(), path)
        if again is not path:
            same = "" if again == path else f" (as {again})"
            raise PipelineError(f"{option} names {path} more than once{same}; give each file once")


def comma_items(text: str) -> list[str]:
    """A comma list's items, stripped; an empty item (``5,,7``, ``2,``) may stand for a value left out, so it
    is refused (argparse's one line), where the list types had dropped it silently."""
    items = [item.strip() for item in text.split(",")]
    if items == [""]:
        raise argparse.ArgumentTypeError("expected values separated by commas, got ''")
    if not all(items):
        raise argparse.ArgumentTypeError(
            f"an empty item in {text[:64]!r}; separate the values by single commas"
        )
    return items


def first_repeat(values: Sequence[T]) -> T | None:
    """The first value of ``values`` that an earlier one equals, or None (for options naming each once)."""
    return next((v for i, v in enumerate(values) if v in values[:i]), None)


def humans_list(text: str) -> tuple[int, ...]:
    """An argparse type: ``5,6,7`` -> (5, 6, 7), positive integers, each once (``--humans`` of sweep and
    calibrate: a repeat would be a second column of the same cells)."""
    try:
        values = tuple(int(v) for v in comma_items(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--humans takes integers like 5,6,7, got {text!r}") from None
    if not values or min(values) < 1:
        raise argparse.ArgumentTypeError(f"--humans needs positive numbers, got {text!r}")
    repeated = first_repeat(values)
    if repeated is not None:
        raise argparse.ArgumentTypeError(f"--humans names {repeated} more than once, got {text!r}")
    return values


def check_writable(
    path: Path | None,
    option: str,
    *,
    directory: bool = False,
    inputs: Iterable[Path] = (),
    json_only: bool = False,
    zoo_own: bool = False,
    room: int | None = None,
    renamed: bool = False,
) -> None:
    """Refuse an output ``path`` that cannot be written, before any work (``None``: the option was not given).

    ``directory``: the path is a directory the command creates or writes into, else a file it creates or
    replaces. What does not exist yet is judged by its nearest existing ancestor, which must be a directory
    the command may create entries in; the check creates nothing (a probe file is made and removed at once).
    A file output is never one of the command's ``inputs`` (``review RUN.mcap --json RUN.mcap`` replaced the
    recording by its summary), and with ``json_only`` (a ``--json`` report) it replaces only a JSON document:
    a mistyped name must not overwrite a data file, a recording or weights. A file output that is a symbolic
    link is refused: one planted in a folder would send the output wherever it points. Nor is an output a
    zoo's own file (its manifest, calibrations, lock; ``check_not_zoo_file``), existing or not, nor in the
    shipped zoo, nor a user zoo entry's weights or config (``check_not_in_a_zoo``), unless ``zoo_own``: the
    command keeps that very file (calibrate's calibrations.json). ``room``: how many bytes
    longer than the output's name the temporary name it is first made under beside it is, which its name
    must leave room for (default: ``REPLACE_FILE_ROOM`` for a file, made by ``replace_file``; 0 for a
    directory, written into; 0 for a figure, whose temporary's name does not grow with the output's:
    ``whole_files.save_figure``). ``renamed``: the file is made under that temporary name and renamed into
    place, so a device or a pipe there is refused: the rename replaced the node itself (``data synth --out
    /dev/null``, run as root, left a regular file there). Standard output (``--json -``,
    ``standard_output.STDOUT``) is no file and needs no check.
    """
    if path is None or is_stdout(path):
        return
    path = Path(path)
    shown = str(path)  # a path of 800 kB from a file is no 800 kB error line
    label = f"{option} {shown if len(shown) <= 1024 else shown[:800] + '...' + shown[-200:]}"
    try:
        os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        pass  # judged below
    except (OSError, ValueError) as exc:  # a name too long, a NUL byte (a TOML escape), no permission
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise PipelineError(f"{label}: not a usable path ({why})") from None
    if room is None:
        room = 0 if directory else REPLACE_FILE_ROOM
    if room and len(os.fsencode(path.name)) > NAME_MAX - room:  # fits, but a sibling not
        raise PipelineError(
            f"{label}: not a usable path (a name of at most {NAME_MAX - room} bytes: crowdmpc writes it "
            "under a longer temporary name first)"
        )
    if not zoo_own:
        check_not_zoo_file(path, label)
        check_not_in_a_zoo(path, option, label)
    if not directory and path.is_symlink():
        # a link planted in a folder would make the output land wherever it points (even where nothing is)
        raise PipelineError(
            f"{label}: is a symbolic link; crowdmpc does not write through one (name its target)"
        )
    if path.exists():
        _check_existing(path, label, directory, inputs, json_only, renamed)
    else:
        _check_creatable(path, label)


def _check_existing(
    path: Path, label: str, directory: bool, inputs: Iterable[Path], json_only: bool, renamed: bool
) -> None:
    """``check_writable`` of an output that exists: of the kind asked for, and writable as it is."""
    if directory != path.is_dir():
        raise PipelineError(f"{label}: " + ("not a directory" if directory else "is a directory"))
    if renamed and not path.is_file():  # before the open below, which waits for a pipe's reader
        raise PipelineError(f"{label}: is not a regular file (a device or a pipe); name a file")
    if not directory:
        _check_not_input(path, label, inputs)
        if json_only:
            _check_json_document(path, label)
    try:
        if directory:
            _probe(path)
        elif path.is_fifo():  # opened and closed, it ends the output its reader waits for: asked instead
            if not os.access(path, os.W_OK):
                raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))
        else:
            open(path, "ab").close()  # neither its contents nor its modification time change
    except OSError as exc:
        raise PipelineError(f"{label}: cannot write there ({exc.strerror or exc})") from None


def _check_creatable(path: Path, label: str) -> None:
    """``check_writable`` of an output that does not exist yet: its nearest existing ancestor is a directory
    the command may create entries in."""
    ancestor = path
    while not ancestor.exists() and ancestor != ancestor.parent:
        if ancestor.is_symlink():  # dangling or a loop: nothing can be made through it (mkdir: File exists)
            raise PipelineError(
                f"{label}: {ancestor} is a symbolic link to nothing (its target is missing or loops)"
            )
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise PipelineError(f"{label}: {ancestor} is not a directory")
    try:
        _probe(ancestor)
    except OSError as exc:
        raise PipelineError(f"{label}: cannot create it in {ancestor} ({exc.strerror or exc})") from None


def _check_not_input(path: Path, label: str, inputs: Iterable[Path]) -> None:
    for source in inputs:
        try:
            same = os.path.samefile(path, source)
        except OSError:  # an input that does not exist is its own command's error
            continue
        if same:
            raise PipelineError(f"{label}: that is one of the command's inputs; write the output elsewhere")


def _check_json_document(path: Path, label: str) -> None:
    """Refuse to replace a file that is not empty and is not a JSON report: a data file, or a JSON file
    crowdmpc keeps: a sweep's and a training run's own files by name, and every document that names a
    crowdmpc format (zoo manifests, predictor configs, calibrations, prepared data manifests)."""
    from pipelines.commands.train_resume import SETTINGS_FILE
    from pipelines.experiments.log import SWEEP_FILE

    refusal = PipelineError(
        f"{label}: the file exists and is not a JSON report; crowdmpc does not overwrite it (remove it "
        "or name another file)"
    )
    try:
        size = path.stat().st_size
        if size == 0:
            return
        if size > MAX_REPORT_BYTES:
            raise ValueError("too large for a report")
        document = json.loads(path.read_bytes())
    except (OSError, ValueError, RecursionError):
        raise refusal from None
    kept = isinstance(document, dict) and str(document.get("format", "")).startswith("crowdmpc")
    if kept or path.name in (SWEEP_FILE, SETTINGS_FILE) or path.name.endswith(".metrics.json"):
        raise PipelineError(
            f"{label}: that is a file crowdmpc keeps (a zoo's, a sweep's or a training run's), not a report; "
            "name another file"
        )


def replace_file(path: Path, write: Callable[[str], object]) -> None:
    """``write(name)`` fills a new file beside ``path``, which then replaces ``path`` in one rename: a write
    that fails (a full disk, ``ulimit -f``) leaves an earlier ``path`` as it was, and no half file. The new
    file gets the mode of the file it replaces (else the umask's). ``OSError`` on failure, the temporary
    file removed; ``path`` must not be a device or a pipe (the rename would replace the node itself). The
    temporary is locked while it is written, and those a killed writer left beside ``path`` are removed."""
    import re

    remove_killed_temporaries(path.parent, re.compile(rf"\.{re.escape(path.name)}\.[a-z0-9_]{{8}}\.part"))
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    fill_and_rename(fd, name, path, write)


def write_output(path: Path, text: str, option: str) -> None:
    """Write ``text`` to the user-named output ``path`` (``--json FILE``), whole or not at all; a failure is a
    one-line PipelineError naming the option (the CLI's message, not an OSError traceback). ``STDOUT``
    (``--json -``): on standard output."""
    if is_stdout(path):
        write_document(text, option)
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.exists() and not path.is_file():  # /dev/null, a pipe: written in place, never replaced
            path.write_text(text, encoding="utf-8")
            return
        try:
            replace_file(path, lambda name: Path(name).write_text(text, encoding="utf-8"))
        except PermissionError:  # a folder without new files but a writable file: in place, as before
            if not path.is_file():
                raise
            path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise PipelineError(f"{option} {path}: could not write it ({exc.strerror or exc})") from None


def _probe(directory: Path) -> None:
    """Create and remove a file in ``directory``: the one test of writability that a read-only file system,
    ACLs and root's privileges all answer truthfully."""
    fd, name = tempfile.mkstemp(prefix=".crowdmpc-probe-", dir=directory)
    os.close(fd)
    os.unlink(name)


def stdout_reader_left() -> bool:
    """Whether stdout is a pipe (or socket) whose reading end is closed (``crowdmpc review ... | head`` after
    ``head`` exited); False when stdout is a terminal, a file, or cannot be asked."""
    try:
        fd = sys.stdout.fileno()
        if not (stat.S_ISFIFO(os.fstat(fd).st_mode) or stat.S_ISSOCK(os.fstat(fd).st_mode)):
            return False
        import select

        poller = select.poll()  # POSIX; the writing end of a pipe without readers polls as POLLERR
        poller.register(fd, select.POLLOUT)
        return any(events & (select.POLLERR | select.POLLHUP) for _, events in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # no fileno (captured output), closed, no poll
        return False


def quit_closed_stdout() -> int:
    """After a write to a stdout whose reader left: the rest of the output goes to /dev/null (Python flushes
    stdout once more at exit, which would raise again) and the status is ``CLOSED_PIPE_STATUS``, as for a
    tool that SIGPIPE ended; no traceback, the reader has what it wanted."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    finally:
        os.close(devnull)
    return CLOSED_PIPE_STATUS
