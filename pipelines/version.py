"""The installed crowdmpc's version and the code it runs: what the CLI prints and every log and sweep records.

``crowdmpc_version()`` is the package's version, which stays 0.1.0 while results change from commit to commit;
``code_identity()`` adds what tells two codebases apart: the git commit of the source tree (when it is a git
checkout, as a clone is; None for an installed wheel), whether tracked files differ from it, and the versions
of the libraries the numbers depend on.
"""

from __future__ import annotations

import functools
import subprocess
import sys
from collections.abc import Iterable
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any, Final

# Libraries whose versions can change results: the solvers, the networks, the arrays.
RESULT_LIBRARIES: Final[tuple[str, ...]] = ("casadi", "torch", "numpy")
SOURCE_ROOT: Final[Path] = Path(__file__).resolve().parents[1]


@functools.cache
def crowdmpc_version() -> str:
    """Looked up once: importlib.metadata scans every distribution."""
    try:
        return version("crowdmpc")
    except PackageNotFoundError:  # running from a source tree that was not installed
        return "0+unknown"


@functools.cache
def code_identity() -> dict[str, str | bool | None]:
    """``{"version", "commit", "dirty", "diff_sha256", "python", "casadi", "torch", "numpy"}``, looked up once
    a process; ``diff_sha256``: of ``git diff HEAD`` (tracked files) when dirty, else None. Outputs record
    ``pipelines.plugins.code_with_plugins()``: this and the plugins' files."""
    commit, dirty = _git_state(SOURCE_ROOT)
    identity: dict[str, str | bool | None] = {
        "version": crowdmpc_version(),
        "commit": commit,
        "dirty": dirty,
        # which uncommitted changes: two runs of one dirty commit were told apart by nothing
        "diff_sha256": _diff_sha256(SOURCE_ROOT) if dirty else None,
        "python": sys.version.split()[0],
    }
    for name in RESULT_LIBRARIES:
        identity[name] = library_version(name)
    return identity


def library_version(name: str) -> str | None:
    """The installed version of distribution ``name``, None where it is not installed."""
    try:
        return version(name)
    except PackageNotFoundError:
        return None


def code_changes(earlier: Iterable[Any], now: dict[str, Any]) -> str:
    """What differs between ``now`` (this process's code: ``pipelines.plugins.code_with_plugins()``) and the
    identities earlier runs recorded, as the resume notes name it: "commit 0123456789ab -> 89abcdef0123,
    torch ..." (each key as the first earlier identity that differs had it; "plugin module:Class" for each
    plugin's file that differs, "(none)" on the side without it; a commit that is None "(no git commit)"), led
    by "code not recorded -> commit ..." when one is no identity (a run from before the code was recorded),
    "code not recorded -> (no git commit, crowdmpc 0.1.0, Python ...)" where this code names no commit (an
    installed wheel); "" when every one is this code.
    Uncommitted changes are compared by their diff's sha256 ("dirty" alone says nothing of which), where the
    earlier identity recorded one."""
    changed: dict[str, Any] = {}
    unrecorded = False
    for before in earlier:
        if not isinstance(before, dict):
            unrecorded = True
            continue
        for k in now:
            if k in ("dirty", "plugins") or (k == "diff_sha256" and k not in before):
                continue
            if before.get(k) != now[k]:
                changed.setdefault(k, before.get(k))
        # each plugin's file on its own, one added or dropped too ("(none)" on the side that lacks it)
        was = _plugin_items(before)
        for key in sorted({key for key, _ in was.items() ^ _plugin_items(now).items()}):
            changed.setdefault(key, was.get(key, "(none)"))
    current = now | _plugin_items(now)
    shown = ", ".join(
        f"{k} {_value_text(k, was)} -> {_value_text(k, current.get(k, '(none)'))}"
        for k, was in changed.items()
    )
    if unrecorded:
        shown = f"code not recorded -> {_this_code_text(now)}" + (f", {shown}" if shown else "")
    return shown


def _value_text(key: str, value: Any) -> str:
    """A recorded value as ``code_changes`` shows it, 12 characters; a commit that is None, said to be none
    (an installed wheel's, a `ray job submit` copy's): "commit None" read as a commit of that name."""
    return "(no git commit)" if key == "commit" and value is None else str(value)[:12]


def _this_code_text(now: dict[str, Any]) -> str:
    """What ``now``'s code is, in one item of ``code_changes``' list: its commit, or, for code without one,
    its versions in parentheses (as ``no_commit_text`` says them: their commas are no items of the list)."""
    if now.get("commit") is not None:
        return f"commit {str(now['commit'])[:12]}"
    return f"({no_commit_text(now) or 'no git commit'})"


def _plugin_items(identity: dict[str, Any]) -> dict[str, Any]:
    """An identity's plugins as "plugin module:Class" -> its file's sha256 (none recorded: none)."""
    plugins = identity.get("plugins")
    return {f"plugin {spec}": sha for spec, sha in plugins.items()} if isinstance(plugins, dict) else {}


def dirty_text(dirty: Any, diff_sha256: Any) -> str:
    """How a commit's name goes on for a tree with uncommitted changes: "+dirty:0123abcd" (their diff's
    sha256, where recorded), "+dirty" (where not), "" for a clean tree."""
    if not dirty:
        return ""
    return "+dirty" + (f":{diff_sha256[:8]}" if isinstance(diff_sha256, str) and diff_sha256 else "")


# The versions a run's recorded code names besides its commit, and their labels: what table.md's "Code:" line
# and compare's code name of it, in this order.
CODE_VERSIONS: Final[tuple[tuple[str, str], ...]] = (
    ("version", "crowdmpc"),
    ("python", "Python"),
    ("casadi", "CasADi"),
    ("torch", "torch"),
    ("numpy", "numpy"),
)


def versions_text(code: dict[str, Any]) -> list[str]:
    """The versions ``code`` (a recorded ``code_identity``) names: "crowdmpc 0.1.0", "Python 3.11.7", ..."""
    return [f"{label} {code[key]}" for key, label in CODE_VERSIONS if code.get(key)]


def no_commit_text(code: dict[str, Any]) -> str | None:
    """Recorded code that names no git commit (an installed wheel, a `ray job submit` copy, whose upload
    leaves .git out), as table.md and compare say it: "no git commit, crowdmpc 0.1.0, Python 3.11.7, ...",
    its versions being all that tells such code apart; None where it names no version either (nothing of
    the code was recorded)."""
    versions = versions_text(code)
    return ", ".join(["no git commit", *versions]) if versions else None


def _diff_sha256(root: Path) -> str | None:
    """The sha256 of ``git diff HEAD`` in ``root`` (tracked files; untracked ones are no part of the code a
    clone has), None where git cannot say."""
    import hashlib

    try:
        diff = subprocess.run(
            ["git", "-C", str(root), "diff", "HEAD", "--binary", "--no-ext-diff", "--no-color"],
            capture_output=True,
            timeout=30,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return hashlib.sha256(diff.stdout).hexdigest() if diff.returncode == 0 else None


def _git_state(root: Path) -> tuple[str | None, bool | None]:
    """(HEAD's commit, whether tracked files differ from it) of ``root``; (None, None) when it is no git
    checkout or git is missing (an installed wheel: its version is then the identity)."""
    if not (root / ".git").exists():
        return None, None
    try:
        head = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10
        )
        status = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return None, None
    if head.returncode != 0 or status.returncode != 0:
        return None, None
    return head.stdout.strip(), bool(status.stdout.strip())
