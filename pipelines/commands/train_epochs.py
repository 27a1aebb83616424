"""How many epochs a training run trains in all: ``--epochs``, which a resume may change and otherwise takes
from the run. It defaulted to 25 on a resume too, so a killed 3-epoch run resumed without ``--epochs``
trained to 25 and recorded other weights than the run it continued."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any, Final

from pipelines.commands import replace_file
from pipelines.commands.train_resume import SETTINGS_FILE, early_stopping_state
from pipelines.errors import PipelineError, print_note
from predictors.checkpoint import load_tensors
from predictors.errors import DuplicateKey, unique_keys
from predictors.text_table import counted

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


def _check_not_stopped_early(out: Path, metrics: Path) -> None:
    """PipelineError when the finished run in ``out`` (``metrics``: its NAME.metrics.json) was ended by its
    --patience: a resume would restore the stop's count and end the fit again after an epoch or go on past
    the stop, either way other weights than the run's under its settings. A key given twice in ``metrics`` is
    refused naming it, as in every JSON file a user may edit (``unique_keys``): json kept the last."""
    try:
        document = json.loads(metrics.read_text(encoding="utf-8"), object_pairs_hook=unique_keys)
        training = document.get("training", {})
    except DuplicateKey as exc:  # before ValueError, which it is
        raise PipelineError(f"--resume: {metrics}: {exc}") from None
    # the run's other checks say what is wrong with it; RecursionError: nesting past the stack (json's parser
    # recurses), damage as the others are
    except (OSError, ValueError, AttributeError, RecursionError):
        return
    stopped = training.get("stopped_early_after") if isinstance(training, dict) else None
    if stopped is not None:
        raise PipelineError(
            f"--resume: {out} stopped early after {stopped} epochs (validation ADE had not improved in the "
            f"last {training.get('patience')}, its --patience): it is finished; start a new run with another "
            "--out"
        )


def _stopped_by_patience(out: Path, epochs: int) -> int | None:
    """The epochs the run in ``out`` trained when its --patience ran out (a run cut before its outputs were
    written, or whose count ran out at its last epoch: this resume trains none and writes them,
    ``train_checkpoint.epochs_to_fit``), said on stderr; None for a run it had not stopped. PipelineError
    for ``epochs`` below them (no count it may take: its stop is its end)."""
    last = out / "checkpoints" / "last.ckpt"
    try:
        stopped = stopped_after(load_tensors(last))
    except Exception:  # read and checked before (train_resume.check_last_checkpoint): nothing more to say
        return None
    if stopped is not None and epochs < stopped:
        raise PipelineError(
            f"--resume: {out} stopped early after {stopped} epochs (its --patience); --epochs {epochs} is "
            "fewer: resume it without --epochs to write what its stop left out"
        )
    if stopped is not None:
        print_note(
            f"note: --resume: {out} stopped after {stopped} epochs, its --patience run out; this resume "
            "trains no epoch and writes its outputs"
        )
    return stopped


def check_more_epochs(out: Path, epochs: int, done: int | None, metrics: Path) -> None:
    """PipelineError when a resume would train no epoch: Lightning stops at once, and the run's NAME.pt,
    NAME.json and metrics were written again, recording --epochs where more had trained. The same count
    as the run's passes while the run is not finished (no ``metrics``, its NAME.metrics.json, yet: it stopped
    after training, and this writes what it left out). A finished run its --patience ended is refused too."""
    finished = metrics.is_file()
    if finished:
        _check_not_stopped_early(out, metrics)
    # a finished run asked for no more epochs is refused below, stopped or not
    if (not finished or done is None or epochs > done) and _stopped_by_patience(out, epochs) is not None:
        return
    if done is not None and (epochs < done or (epochs == done and finished)):
        raise PipelineError(
            f"--resume: {out} has trained {counted(done, 'epoch')} already; --epochs {epochs} "
            f"would train none (give more than {done} to continue it)"
        )


def stopped_after(checkpoint: dict[str, Any]) -> int | None:
    """The epochs a run trained when its --patience ran out (``checkpoint``: its last.ckpt, whose
    EarlyStopping state counts the epochs without a gain); None while it had not."""
    stop = early_stopping_state(checkpoint)
    wait, patience = (None, None) if stop is None else (stop.get("wait_count"), stop.get("patience"))
    if isinstance(wait, int) and isinstance(patience, int) and wait >= patience:
        return int(checkpoint["epoch"]) + 1
    return None
