"""The paths a command writes, as it reads them from its options and config: ``..`` after a folder that does
not exist is taken away with that folder, before anything is made.

``mkdir(parents=True)`` on ``NEW/x/../run`` had to create ``NEW/x`` to follow the ``..``, and left it behind
empty, whether the command then wrote ``NEW/run`` or refused. Only a missing folder's ``..`` goes: where the
part before ``..`` exists it stays, so that a symbolic link keeps its meaning (``link/..`` is the parent of
the link's target, as the OS resolves it, not the folder holding the link). A leaf: commands and the
benchmark scripts import it, it imports nothing of theirs."""

from __future__ import annotations

import argparse
import os
from pathlib import Path


def without_missing_parents(path: Path) -> Path:
    """``path`` with each ``..`` that follows a folder that does not exist removed along with that folder
    (``NEW/x/../run`` -> ``NEW/run``); every other part as written. Relative paths are judged from the
    current directory, as the command will use them."""
    if ".." not in path.parts:
        return path
    kept: list[str] = []
    for part in path.parts:
        if part == ".." and kept and kept[-1] != ".." and not os.path.lexists(Path(*kept)):
            kept.pop()  # nothing there: the OS would make it only to step out of it
        else:
            kept.append(part)
    return Path(*kept) if kept else Path(".")


def output_arg(text: str) -> Path:
    """An argparse ``type`` for an output option: a path, ``without_missing_parents``. An empty value (an
    unset shell variable) is refused, as ``path_arg`` refuses it: ``Path("")`` is the current directory. So
    is "-", standard output to every tool (``--json -`` here), where these outputs are files or folders: it
    made one called "-" (``data synth --out -``), which "./-" still names."""
    if not text:
        raise argparse.ArgumentTypeError("must be a path, got ''")
    if text == "-":
        raise argparse.ArgumentTypeError(
            "got '-' (standard output), but this output is a file or folder; name one "
            "(./- for one called '-')"
        )
    return without_missing_parents(Path(text))


def file_output_arg(text: str) -> Path:
    """``output_arg`` for an output that is a file: a folder's name is refused (``names_a_folder``)."""
    path = output_arg(text)
    check_names_a_file(text)
    return path


def names_a_folder(text: str) -> bool:
    """Whether ``text`` names a folder by its ending (``runs/``, ``runs/.``) that ``Path`` drops, making it a
    file's name: ``data synth --out runs/`` wrote a file called runs. Others (``/``, ``./``, ``x/..``) keep
    naming a folder, which the write itself refuses."""
    return os.path.basename(text) in ("", ".") and Path(text).name not in ("", "..")


def check_names_a_file(text: str) -> None:
    """ArgumentTypeError where ``text``, an output that is a file, names a folder (``names_a_folder``)."""
    if names_a_folder(text):
        raise argparse.ArgumentTypeError(
            f"got {text!r}, a folder, but this output is a file; name a file in it"
        )
