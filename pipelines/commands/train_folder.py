"""The folder a ``crowdmpc train`` writes into, checked before anything is read or written: missing, empty
or a training run's (what ``--resume`` continues, or a new run replaces while it holds no outputs yet), with
Lightning's folders in it folders (pipelines.commands.train)."""

from __future__ import annotations

from pathlib import Path

from pipelines.commands.train_report import finished_outputs
from pipelines.commands.train_resume import LOCK_FILE, SETTINGS_FILE
from pipelines.errors import PipelineError


def check_run_folder(out: Path, resume: bool) -> None:
    """PipelineError unless --out is a folder a run may write into: missing, empty, or a training run's
    (what ``--resume`` continues, or a new run replaces while it has no last.ckpt nor NAME.pt or metrics);
    Lightning's folders in it must be folders, none a symbolic link."""
    for folder in ("checkpoints", "csv", "tensorboard"):  # Lightning writes into them (train_fit._trainer)
        if (out / folder).is_symlink():
            raise PipelineError(
                f"--out {out}: its {folder} is a symbolic link; crowdmpc does not write through one "
                "(remove it)"
            )
        if (out / folder).exists() and not (out / folder).is_dir():  # Lightning's makedirs: a traceback
            raise PipelineError(f"--out {out}: its {folder} is not a directory (remove it)")
    last = out / "checkpoints" / "last.ckpt"
    # a resume said "does not exist", and a new run saved its last checkpoint inside the folder
    if last.exists() and not last.is_file():
        what = "a folder" if last.is_dir() else "a special file"
        if resume:
            raise PipelineError(f"--resume: {last} is {what}, not a checkpoint (nothing to resume in {out})")
        raise PipelineError(f"--out {out}: its checkpoints/last.ckpt is {what}, not a checkpoint (remove it)")
    if resume and not last.is_file():
        raise PipelineError(f"--resume: {last} does not exist (nothing to resume in {out})")
    if not resume and last.is_file():
        raise PipelineError(f"{out} already holds a training run; pass --resume to continue it or pick --out")
    if not resume and not _holds_a_run_or_nothing(out):
        # the run's checkpoints, logs and NAME.pt would be mixed with the user's files (sweep and data
        # prepare refuse such a folder too)
        raise PipelineError(
            f"--out {out} holds files but no training run ({SETTINGS_FILE} or checkpoints/last.ckpt of "
            "`crowdmpc train`); a run would write among them: choose an empty or new folder"
        )
    # its checkpoints/ removed (to save space); after the check above: one's own folder with a .pt is no run
    if not resume and (finished := finished_outputs(out)):
        raise PipelineError(
            f"{out} holds a finished run's {', '.join(finished)} but no checkpoints/last.ckpt to resume; a "
            "new run would replace them: choose another --out, or remove them"
        )


def _holds_a_run_or_nothing(out: Path) -> bool:
    """Whether ``out`` is missing, empty or a training run's folder, which holds its settings from before
    its first epoch (a run from before they were kept holds a last.ckpt, refused before this without
    --resume). The lock alone is a run's too: it is left in a folder the run did not make when the run
    fails before writing anything, as is the settings' temporary when a kill stops their write."""
    if not out.is_dir():
        return True
    names = {entry.name for entry in out.iterdir()}
    leftovers = {n for n in names if n.startswith(f".{SETTINGS_FILE}.") and n.endswith(".part")}
    # a folder made ready for runs holds a .gitkeep or the like, which the run's files leave alone
    hidden = {n for n in names if n.startswith(".") and (out / n).is_file() and not (out / n).is_symlink()}
    return SETTINGS_FILE in names or not names - leftovers - hidden - {LOCK_FILE}
