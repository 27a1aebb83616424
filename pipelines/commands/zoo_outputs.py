"""Where a command's outputs may not go: a zoo's own files (``pipelines.commands.check_writable`` asks)."""

from __future__ import annotations

import os
from pathlib import Path

from pipelines.errors import PipelineError


def check_outside_the_zoos(
    path: Path, option: str, what: str, which: tuple[str, ...] = ("shipped", "user")
) -> None:
    """Refuse an output ``path`` in the shipped or the user zoo (symbolic links followed): their files are
    what their manifests' sha256 record, and only `crowdmpc zoo add` writes them; an export over NAME.pt, or
    a training run writing its NAME.pt there, left an entry that never loads again. ``what`` is the output
    the message asks to put elsewhere."""
    from predictors import zoo
    from predictors.errors import PredictorError

    try:
        target = path.resolve()
    except (OSError, RuntimeError):  # a symbolic link loop, in no zoo: check_writable refuses it
        return
    for name, locate in (("shipped", zoo.checkpoints_dir), ("user", zoo.user_zoo_dir)):
        if name not in which:
            continue
        try:
            root = locate().resolve()
        except (PredictorError, OSError, RuntimeError):  # no such zoo here, so the path cannot be in it
            continue
        if target.is_relative_to(root):
            raise PipelineError(
                f"{option} {path} lies in the {name} zoo {root}, whose files only `crowdmpc zoo add` "
                f"writes; write {what} elsewhere"
            )


def check_not_in_a_zoo(path: Path, option: str, label: str) -> None:
    """Refuse an output anywhere in the shipped zoo (tracked in git, verified by sha256: `simulate --record
    checkpoints` wrote among its weights), or at a user zoo entry's weights or config (a report named so
    replaced them). Beside the entries the user zoo takes other files: it is the folder a user names with
    ``CROWDMPC_ZOO=DIR``, where their reports may well go."""
    from predictors import zoo
    from predictors.errors import PredictorError

    check_outside_the_zoos(path, option, "it", which=("shipped",))
    try:
        root = zoo.user_zoo_dir()
        entries = zoo.read_manifest(root).values() if root.is_dir() else ()
        target = path.resolve()
    except (PredictorError, OSError, RuntimeError):  # no user zoo, or none readable: no entry to keep
        return
    for entry in entries:
        for what, name in (("weights", entry.file), ("config", entry.config)):
            if _same_file(target, root / name):
                raise PipelineError(
                    f"{label}: that is the {what} of the user zoo's entry {entry.name!r}; name another file"
                )


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a == b.resolve()
    except (OSError, RuntimeError):
        return False


def check_not_zoo_file(path: Path, label: str) -> None:
    """Refuse ``path`` when it is the user zoo's or the shipped zoo's own file, whether it exists yet or not:
    a report written there before the zoo made the file (``calibrate --json ZOO/calibrations.json`` on a new
    zoo) took its place, and every later command that reads the zoo failed on it."""
    from predictors.errors import PredictorError
    from predictors.manifest import ZOO_FILES, zoo_file
    from predictors.zoo import checkpoints_dir, user_zoo_dir

    own = zoo_file(path.name)
    if own is None:
        return
    for zoo_dir in (user_zoo_dir, checkpoints_dir):
        try:
            root = zoo_dir()
        except PredictorError:  # no home directory, no shipped zoo: no such file to protect
            continue
        if _same_directory(path.parent, root):
            raise PipelineError(
                f"{label}: that is a file of the zoo {root}, its {ZOO_FILES[own]}; name another file"
            )


def _same_directory(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name one directory: the same file where both exist (a case-insensitive file
    system, links), else the same path once resolved (a zoo not made yet)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        pass
    try:
        return a.resolve() == b.resolve()
    except (OSError, RuntimeError):  # a symbolic link loop: not a zoo
        return False
