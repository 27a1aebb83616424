"""Errors a user can cause through the pipelines (bad files, bad options), and the one a sweep stops itself
with (SweepStopped). Printed without a traceback."""

from __future__ import annotations

import contextlib
import errno
import sys
import unicodedata
import warnings
from collections.abc import Iterator
from typing import Any, TextIO

# The errno of a write that the storage refused: a full disk (ENOSPC), a quota (EDQUOT), a file size limit
# (EFBIG, `ulimit -f`), a file system remounted read-only (EROFS). None is a bug of ours: the user frees space
# and runs the command again, so the CLI says so in one line rather than in a traceback.
STORAGE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS})

# The exit status of a run an episode's error stopped (simulate, calibrate: the episode named by its seed,
# what finished reported) and of a sweep some of whose episodes raised (each in its errors.jsonl): what ran
# is kept, where a refused input (2) ran nothing, and a script tells the two apart.
EPISODES_RAISED = 1


class PipelineError(ValueError):
    """Base class of the user-facing errors raised by `pipelines`."""


class RecordingRefused(PipelineError):
    """``--record`` cannot write an episode's file (another run's episode there, a link, no lock): a refusal
    of the folder the user named, not a failure of the episode."""


class SweepStopped(PipelineError):
    """A sweep that stopped itself part way (its first episodes all raised, its workers kept dying): what it
    recorded stands, and gets its report. ``workers``: the episodes its backend ran at once (None: none
    started, or it did not say), which the report's CPU projection divides by."""

    def __init__(self, message: str, workers: int | None = None):
        super().__init__(message)
        self.workers = workers


class EpisodeFailed(PipelineError):
    """A user's error raised inside one episode of ``run_episodes`` (a plugin breaking its contract or
    raising), with the episode that failed named first: ``simulate --seed SEED --episodes 1`` reruns it."""

    def __init__(self, seed: int, scenario: str, error: Exception | str):
        super().__init__(f"episode seed {seed} ({scenario}): {error}")
        self.seed = seed
        self.scenario = scenario
        self.error = str(error)  # its line: the error itself travels as the cause, which pickle drops

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        # Built from its facts, as predictors.errors.DatasetFormatError: a process pool sends a job's
        # exception back pickled, and BaseException's pickle calls the class with the message alone.
        return type(self), (self.seed, self.scenario, self.error)


def one_line(text: str) -> str:
    """``text`` with its control characters (a newline, a carriage return, an escape sequence) and Unicode's
    line and paragraph separators written as Python escapes (``\\n``, ``\\x1b``): the CLI's error line and its
    notes (``print_note``) name the user's paths and values, and a path holding a newline (``--config
    $'a\\nb.toml'``) ran a line over two. Any other text, every ordinary message included, is returned as it
    is."""
    return "".join(c.encode("unicode_escape").decode("ascii") if _breaks_line(c) else c for c in text)


def print_note(text: str) -> None:
    """Print ``text``, a note or warning of the CLI, on stderr as one line (``one_line``): a note names the
    user's paths and values as an error does, and a path holding a newline ran it over two as well."""
    print(one_line(text), file=sys.stderr)


def _breaks_line(char: str) -> bool:
    """Whether ``char`` is one ``one_line`` escapes: a C0 or C1 control, or U+2028/U+2029."""
    return unicodedata.category(char) in ("Cc", "Zl", "Zp")


def interrupt_behind(exc: BaseException | None) -> KeyboardInterrupt | None:
    """The Ctrl-C behind ``exc``, if it is one a C extension wrapped: a KeyboardInterrupt raised in Python
    code that CasADi calls back during a solve comes out as ``SystemError('... returned a result with an
    exception set')`` caused by it, which a handler of solver failures would otherwise take for one."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def storage_refusal(exc: BaseException) -> str | None:
    """The one line that ends a command whose write the storage refused (``STORAGE_ERRNOS``): the file when
    the error names it, the cause, and what to do; None for any other error (a bug keeps its traceback)."""
    if not isinstance(exc, OSError):
        return None
    if exc.errno not in STORAGE_ERRNOS:
        from predictors.durable import SyncFailed  # not at import: the predictors package loads casadi

        if not isinstance(exc, SyncFailed):
            return None
        return (  # EIO at a file's sync: the storage itself failed
            f"could not write {exc.filename} ({exc.strerror}: its data did not reach the disk); check the "
            "disk or its mount (dmesg) and run the command again"
        )
    # a copy's (shutil.move across file systems, as Lightning's checkpoint save does) names its source first,
    # and the file that could not be written second
    target = exc.filename2 if exc.filename2 is not None else exc.filename
    where = f" {target}" if target is not None else ""
    return (
        f"could not write{where} ({exc.strerror or exc}); free space (or raise the quota, or `ulimit -f`) "
        "and run the command again"
    )


@contextlib.contextmanager
def writes_named(path: object) -> Iterator[None]:
    """An ``OSError`` of a write inside the block that names no file (a full disk fails ``write`` itself,
    whose error carries none) raised again naming ``path``, the output it was making, so that the CLI's
    line (``storage_refusal``) says which; one that names a file already passes as it is, and so does one
    without an errno (a library's ``OSError("...")``, ``io.UnsupportedOperation``): no write the system
    refused, a bug whose traceback read "[Errno None] None: 'PATH'", its message and type gone."""
    try:
        yield
    except OSError as exc:
        if exc.filename is not None or exc.errno is None:
            raise
        raise OSError(exc.errno, exc.strerror, str(path)) from None


class CloseFailed(PipelineError):
    """A controller plugin's ``close()`` raised after every episode of ``run_episodes`` had finished: the
    episodes stand (a report gives them whole), and the run ends as one whose plugin raised."""

    def __init__(self, error: Exception | str, episodes: int):
        after = "its one episode" if episodes == 1 else f"all {episodes} of its episodes"
        super().__init__(f"{error} (after {after} had finished)")
        self.error = str(error)
        self.episodes = episodes

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        return type(self), (self.error, self.episodes)


class NoTwinWarning(RuntimeWarning):
    """A predictor whose CasADi twin could not be exported, run in torch instead (pipelines.loop.mpc):
    slower, and said once for each size of the NLP."""


class FlockWarning(UserWarning):
    """Robots bound for separate places whom Eq. 15, every pair flocking, may hold together (pipelines.loop
    .team_layout.warn_separate_goals; MPCConfig.flock_range)."""


class DroppedLineWarning(UserWarning):
    """A sweep's episodes.jsonl ended in a whole line that is no JSON record, cut off and kept beside it
    (pipelines.experiments.log.EpisodeLog.scan)."""


class GoalRoomWarning(UserWarning):
    """Two robots' goals closer than the MPC lets robots stand (pipelines.loop.team_layout.warn_goal_room;
    Eq. 12 keeps every pair d_min apart)."""


class ActBeforeResetWarning(UserWarning):
    """A controller's ``act`` before any ``reset`` (pipelines.loop.mpc), said once per controller: the checks
    of the robots' layout that reset makes were skipped. Not a refusal: a benchmark may time ``act`` alone.
    Not a ``LayoutWarning`` either: it is about the calls, and ignoring layouts must not hide it."""


def act_before_reset(controller: str) -> ActBeforeResetWarning:
    """The warning of ``controller``'s first ``act`` before any ``reset``: what it skips, and the way out."""
    return ActBeforeResetWarning(
        f"{controller}.act called before reset: the checks reset makes on the robots' layout (FlockWarning, "
        "GoalRoomWarning) are skipped, and a size prepare() did not build is built inside this step; call "
        "reset(obs) at the start of each episode (said once per controller)"
    )


def quiet_team_warnings() -> None:
    """Leave out the controller's warnings on the robots' layout (``FlockWarning``, ``GoalRoomWarning``),
    which ``simulate`` and ``sweep`` say once, before the first episode, in their own words
    (pipelines.commands.team_notes); a sweep's workers each said them again. Inside
    ``warnings.catch_warnings()``. Only those of a controller crowdmpc's loops reset (the warning names
    the caller of the MPC's ``reset``): a plugin around ``MPCController`` resets it from its own module,
    gets no note, and keeps the warning as its only word on the layout."""
    for category in (FlockWarning, GoalRoomWarning):
        warnings.filterwarnings("ignore", category=category, module=r"pipelines\.")


def warnings_as_notes() -> None:
    """Show crowdmpc's own warnings (agents laid out in contact, a predictor run without its twin) as the
    commands' other notes, "note: ..." on one line, not as Python's file, line and source line; any other
    warning as Python shows it. For the CLI and its worker processes; a library user keeps Python's."""
    from crowdsim.errors import LayoutWarning

    shown = warnings.showwarning
    if getattr(shown, "crowdmpc_notes", False):
        return

    def show(
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        file: TextIO | None = None,
        line: str | None = None,
    ) -> None:
        ours = (
            LayoutWarning
            | NoTwinWarning
            | FlockWarning
            | GoalRoomWarning
            | DroppedLineWarning
            | ActBeforeResetWarning
        )
        if not issubclass(category, ours):
            shown(message, category, filename, lineno, file, line)
        elif (out := file or sys.stderr) is not None:
            with contextlib.suppress(OSError):  # as Python's own: a note lost to a closed pipe raises nothing
                print(f"note: {one_line(str(message))}", file=out)

    show_any: Any = show
    show_any.crowdmpc_notes = True
    warnings.showwarning = show
