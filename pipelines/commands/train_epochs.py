"""How many epochs a training run trains in all: ``--epochs``, which a resume may change and otherwise takes
from the run. It defaulted to 25 on a resume too, so a killed 3-epoch run resumed without ``--epochs``
trained to 25 and recorded other weights than the run it continued."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any, Final

from pipelines.commands import replace_file
from pipelines.commands.train_resume import SETTINGS_FILE
from pipelines.errors import PipelineError

DEFAULT_EPOCHS: Final[int] = 25


def take_run_epochs(args: argparse.Namespace, out: Path, recorded: dict[str, Any] | None) -> list[str]:
    """``args.epochs`` when typed; else on a resume the run's (``recorded``: its settings file), else the
    default. Returns ["epochs"] when taken from the run (for ``say_taken``). A run that recorded no count
    (started before the settings file held it) cannot say how long it was to train: PipelineError asking
    for --epochs, rather than 25 as a guess."""
    if args.epochs is not None:
        return []
    if not args.resume:
        args.epochs = DEFAULT_EPOCHS
        return []
    last = out / "checkpoints" / "last.ckpt"
    if recorded is None and not last.exists():  # no run there: said so, as with --epochs typed
        raise PipelineError(f"--resume: {last} does not exist (nothing to resume in {out})")
    epochs = (recorded or {}).get("epochs")
    if isinstance(epochs, bool) or not isinstance(epochs, int) or not 1 <= epochs:
        raise PipelineError(
            f"--resume: {out} does not record how many epochs it trains in all (a run started before the "
            "count was kept); give --epochs N"
        )
    args.epochs = epochs
    return ["epochs"]


def record_epochs(out: Path, recorded: dict[str, Any], epochs: int) -> None:
    """Write ``epochs`` into the run's settings file (``recorded``, as read) when a resume changed it, so that
    the next resume without --epochs goes on to this count (its other settings were checked equal)."""
    if recorded.get("epochs") == epochs:
        return
    text = json.dumps({**recorded, "epochs": epochs}, indent=2) + "\n"
    replace_file(out / SETTINGS_FILE, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def check_more_epochs(out: Path, epochs: int, done: int | None, finished: bool) -> None:
    """PipelineError when a resume would train no epoch: Lightning stops at once, and the run's NAME.pt,
    NAME.json and metrics were written again, recording --epochs where more had trained. The same count
    as the run's passes while the run is not ``finished`` (no metrics yet: it stopped after training, and
    this writes what it left out)."""
    if done is not None and (epochs < done or (epochs == done and finished)):
        raise PipelineError(
            f"--resume: {out} has trained {done} epoch{'s' if done != 1 else ''} already; --epochs {epochs} "
            f"would train none (give more than {done} to continue it)"
        )
