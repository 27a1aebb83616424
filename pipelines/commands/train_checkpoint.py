"""The callbacks of ``crowdmpc train``: its checkpoints, its stop on divergence (and what it says of one),
its clock and its progress, and the epochs a resumed fit goes to (imported with Lightning, when a run
starts)."""

from __future__ import annotations

import argparse
import contextlib
import csv
import math
import os
import re
import sys
import time
from pathlib import Path
from typing import Any, Final

import torch
from lightning.pytorch.callbacks import Callback, ModelCheckpoint, TQDMProgressBar
from lightning.pytorch.loggers import CSVLogger
from lightning.pytorch.plugins import TorchCheckpointIO

from pipelines.commands import replace_file
from pipelines.commands.train_epochs import stopped_after
from pipelines.commands.train_resume import relocated
from pipelines.errors import PipelineError, print_note
from pipelines.whole_files import remove_killed_temporaries
from predictors.checkpoint import load_checkpoint, load_tensors
from predictors.errors import PredictorError


class RunCheckpoint(ModelCheckpoint):
    """Lightning's ModelCheckpoint, resuming a run whose folder was moved or copied as one left in place (the
    paths of its best and last checkpoints are read in its folder now, not in the one they were written in),
    a run killed between Lightning's removal of its previous best and the epoch's last.ckpt as one killed
    before that epoch (the best checkpoints last.ckpt names are the ones still in the folder), and writing
    last.ckpt at every epoch's end. Run with ``enable_version_counter=False``: a run's folder holds its own
    files only, and an epoch trained again replaces the checkpoint its killed first try left, not -v1 beside
    it."""

    @property
    def state_key(self) -> str:
        # ModelCheckpoint's own key: the last.ckpt of a run started before this class still resumes its state
        return super().state_key.replace(type(self).__qualname__, ModelCheckpoint.__qualname__, 1)

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        super().load_state_dict(relocated(state_dict, str(self.dirpath)))
        self._forget_missing()

    def _forget_missing(self) -> None:
        """Drops the best checkpoints the state names that are not in the folder, and finds the best and k-th
        of the rest as Lightning does (``_update_best_and_save``); none left, Lightning finds them again as
        training goes on. A best is removed only once a better one is saved, after the last.ckpt written
        before it: a run killed between the two, as kill -9 can, resumes from a last.ckpt naming a removed
        file (it was refused, or read as the best), and trains the epoch of the better one again."""
        present = {path: score for path, score in self.best_k_models.items() if os.path.isfile(path)}
        if len(present) == len(self.best_k_models) and (
            not self.best_model_path or os.path.isfile(self.best_model_path)
        ):
            return
        best, worst = (min, max) if self.mode == "min" else (max, min)
        self.best_k_models = present
        self.best_model_path = best(present, key=present.__getitem__) if present else ""
        self.best_model_score = present[self.best_model_path] if present else None
        if present and (self.save_top_k == -1 or len(present) == self.save_top_k):
            self.kth_best_model_path = worst(present, key=present.__getitem__)
            self.kth_value = present[self.kth_best_model_path]
        else:  # fewer than k: Lightning keeps every new one, and has no k-th yet
            self.kth_best_model_path = ""
            self.kth_value = torch.tensor(torch.inf if self.mode == "min" else -torch.inf)

    # Lightning (2.6) writes last.ckpt only at an epoch that is a new best: a run stopped after a worse epoch
    # resumed from an earlier one, and a run that ended said it had trained fewer epochs than it had (its
    # --resume trained the same epochs again). Every epoch now writes last.ckpt, where Lightning saves.
    def on_train_epoch_end(self, trainer: Any, pl_module: Any) -> None:
        super().on_train_epoch_end(trainer, pl_module)
        if self._should_save_on_train_epoch_end(trainer):
            self._save_last_unless_saved(trainer)

    def on_validation_end(self, trainer: Any, pl_module: Any) -> None:
        super().on_validation_end(trainer, pl_module)
        if not self._should_save_on_train_epoch_end(trainer):
            self._save_last_unless_saved(trainer)

    def _save_topk_checkpoint(self, trainer: Any, monitor_candidates: dict[str, Any]) -> None:
        # An epoch whose training loss was not finite is no best, whatever its validation ADE: a Gaussian
        # head's NaN sigmas (a negative one's log) leave the mean, and so the ADE, finite, and that epoch was
        # kept as "the best epoch before" the divergence it was, its weights written as a trained model's.
        if not any(isinstance(c, StopOnDivergence) and c.diverging for c in trainer.callbacks):
            super()._save_topk_checkpoint(trainer, monitor_candidates)

    def _save_last_unless_saved(self, trainer: Any) -> None:
        # skipped too when this step is saved already: a new best writes last.ckpt with it
        if not self._should_skip_saving_checkpoint(trainer):
            self._save_last_checkpoint(trainer, self._monitor_candidates(trainer))


# replace_file's temporary of a checkpoint: .NAME.ckpt.XXXXXXXX.part
CHECKPOINT_TEMPORARY: Final[re.Pattern[str]] = re.compile(r"\..+\.ckpt\.[a-z0-9_]{8}\.part")


# what WholeCSVLogger reads of Lightning's _ExperimentWriter (not its public API)
_WRITER_FIELDS: Final[tuple[str, ...]] = ("metrics", "metrics_keys", "metrics_file_path")


class WholeCSVLogger(CSVLogger):
    """Lightning's CSVLogger, whose metrics.csv is rewritten whole or not at all. Lightning writes the file's
    header from the columns logged so far and, when a new one comes, truncates the file and writes it again
    in place. Every run (each version of a resumed one) does so a few times: lr-Adam comes alone in the
    first row, epoch and train_loss at the fifth step (social_gan's own columns with them), the validation
    metrics at the first validation, epoch_time_s and train_loss_epoch at the first epoch's end; a kill -9,
    the OOM killer or a full disk in a rewrite lost every row logged before (measured: vanilla_lstm, 2
    epochs of at most 130 batches: three rewrites, the last of 20 rows). The new header and the rows now go
    to a new file that replaces the old in one rename, and Lightning, finding no new column left, appends
    as ever; the file's bytes are Lightning's. It reads Lightning's writer's own fields (2.4 to 2.6 name them
    alike); a release without them gets Lightning's save as it is, the rewrite in place, not a failed run."""

    def save(self) -> None:
        writer = self.experiment
        if not all(hasattr(writer, field) for field in _WRITER_FIELDS):
            return super().save()
        new = set().union(*writer.metrics) - set(writer.metrics_keys)
        path = Path(writer.metrics_file_path)
        if new and path.is_file():
            columns = sorted({*writer.metrics_keys, *new})
            with path.open(newline="", encoding="locale") as f:  # the encoding Lightning writes in
                rows = list(csv.DictReader(f))

            def write(name: str) -> None:
                with open(name, "w", newline="", encoding="locale") as f:
                    table = csv.DictWriter(f, fieldnames=columns)
                    table.writeheader()
                    table.writerows(rows)

            replace_file(path, write)
            writer.metrics_keys[:] = columns  # Lightning's own rewrite (in place) then has nothing to do
        super().save()


class WholeCheckpointIO(TorchCheckpointIO):
    """Lightning's checkpoint writer, each checkpoint written beside its name and renamed (``replace_file``):
    Lightning's own wrote it to a temporary of the temp directory and moved it in, so a kill -9 in between
    left a copy of the weights and optimiser state in $TMPDIR for good (80 MB for a hidden size of 1024),
    and where $TMPDIR is another file system the move copied, which a kill cut under the checkpoint's name.
    What a killed save leaves beside it, the next save into the folder removes."""

    def save_checkpoint(self, checkpoint: dict[str, Any], path: Any, storage_options: Any = None) -> None:
        if storage_options is not None:  # as Lightning's: none of its savers passes one
            raise TypeError(f"storage_options is not supported by {type(self).__name__}")
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        # every killed save's: a best checkpoint's name holds its val_ade, which the next run may never reach
        remove_killed_temporaries(Path(path).parent, CHECKPOINT_TEMPORARY)
        replace_file(Path(path), lambda name: torch.save(checkpoint, name))


class StopOnDivergence(Callback):
    """Stops the fit after the first epoch whose mean training loss is not finite, and says which. One NaN
    gradient leaves NaN in Adam's moments and in every weight it steps, so no later epoch recovers: a
    diverged run trained on to its last epoch, then wrote NaN weights. ModelCheckpoint keeps the best epoch
    before it (it never takes a NaN score for a better one)."""

    def __init__(self) -> None:
        self.epoch: int | None = None  # the epoch whose loss was not finite
        self.loss = math.nan
        self.diverging = False  # a step of this epoch had a loss that is not finite (RunCheckpoint reads it)

    def on_train_epoch_start(self, trainer: Any, pl_module: Any) -> None:
        self.diverging = False

    def on_train_batch_end(
        self, trainer: Any, pl_module: Any, outputs: Any, batch: Any, batch_idx: int
    ) -> None:
        # the step's loss, as both modules log it: the epoch's mean is known only after its validation,
        # when the best checkpoint has been saved
        loss = trainer.callback_metrics.get("train_loss")
        if loss is not None and not bool(torch.isfinite(loss).all()):
            self.diverging = True

    def on_train_epoch_end(self, trainer: Any, pl_module: Any) -> None:
        loss = trainer.callback_metrics.get("train_loss_epoch")
        if loss is not None and not bool(torch.isfinite(loss).all()) and self.epoch is None:
            self.epoch, self.loss = trainer.current_epoch, float(loss)
            trainer.should_stop = True


class TrainingClock(Callback):
    """The seconds a run has trained, kept in its checkpoints: NAME.metrics.json's ``wall_time_s`` of a
    resumed run counted its last part alone. ``before``: its earlier parts' seconds as its last.ckpt holds
    them, each from its fit's start to that checkpoint (a killed part's time after its last checkpoint went
    with the epoch it was training, which the resume trains again). A last.ckpt from before the clock holds
    none: its run counts from the resume, as before."""

    def __init__(self) -> None:
        self.before = 0.0
        self._started: float | None = None

    def on_fit_start(self, trainer: Any, pl_module: Any) -> None:
        self._started = time.perf_counter()

    def state_dict(self) -> dict[str, float]:
        return {"seconds": self.before + self.this_part()}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        seconds = state_dict.get("seconds")
        if isinstance(seconds, int | float) and not isinstance(seconds, bool) and 0 <= seconds < math.inf:
            self.before = float(seconds)

    def this_part(self) -> float:
        """The seconds since this fit started (0 before it has)."""
        return 0.0 if self._started is None else time.perf_counter() - self._started


class StderrProgressBar(TQDMProgressBar):
    """Lightning's bars on stderr, where every command's progress goes: Lightning draws them on stdout
    (``file=sys.stdout``, looked up as each bar is made), so a script reading train's results from stdout
    got the bars' carriage returns and cursor-up escapes among them."""

    def init_sanity_tqdm(self) -> Any:
        return _on_stderr(super().init_sanity_tqdm)

    def init_train_tqdm(self) -> Any:
        return _on_stderr(super().init_train_tqdm)

    def init_validation_tqdm(self) -> Any:
        return _on_stderr(super().init_validation_tqdm)

    def init_test_tqdm(self) -> Any:
        return _on_stderr(super().init_test_tqdm)

    def init_predict_tqdm(self) -> Any:
        return _on_stderr(super().init_predict_tqdm)


def _on_stderr(make: Any) -> Any:
    """``make()``'s bar, made while ``sys.stdout`` is stderr (Lightning names its file then)."""
    with contextlib.redirect_stdout(sys.stderr):
        return make()


class EpochLines(Callback):
    """One line on stderr per epoch, where no terminal shows Lightning's bars (a batch job's log, ``nohup``,
    a pipe): a bar there writes a carriage-return update per refresh, hundreds of kilobytes of them an hour,
    and no line a log reader can follow."""

    def __init__(self) -> None:
        self._started = time.perf_counter()

    def on_train_epoch_start(self, trainer: Any, pl_module: Any) -> None:
        self._started = time.perf_counter()

    def on_train_epoch_end(self, trainer: Any, pl_module: Any) -> None:
        # Lightning validates before this hook within an epoch, so the epoch's val_ade is here
        metrics = trainer.callback_metrics
        shown = [
            f"{label} {float(metrics[key]):.4g}{unit}"
            for key, label, unit in (("train_loss_epoch", "train loss", ""), ("val_ade", "val ADE", " m"))
            if key in metrics
        ]
        seconds = time.perf_counter() - self._started
        print(
            f"epoch {trainer.current_epoch + 1}/{trainer.max_epochs}: {', '.join(shown) or 'no metric yet'} "
            f"({seconds:.1f} s)",
            file=sys.stderr,
            flush=True,
        )


def progress_callbacks(no_progress: bool) -> list[Callback]:
    """Lightning's bars on a terminal (on stderr), one line an epoch elsewhere, nothing with --no-progress."""
    if no_progress:
        return []
    return [StderrProgressBar()] if sys.stderr is not None and sys.stderr.isatty() else [EpochLines()]


def check_weights_fit(last: Path, module: torch.nn.Module) -> None:
    """PipelineError unless ``last``'s weights are the ones ``module`` holds, name for name and shape for
    shape: a plugin net changed since the run started (a layer added) or a hand-edited file otherwise ends
    the resume inside Lightning with a traceback; and unless the rest a resume restores is whole
    (``_check_training_state``)."""
    checkpoint = load_tensors(last)
    held = checkpoint["state_dict"]
    wanted = module.state_dict()
    problems = [f"{key} missing" for key in wanted if key not in held]
    problems += [f"{key} not in the net" for key in held if key not in wanted]
    problems += [
        f"{key} {_shape(held[key])} in the file, {_shape(value)} in the net"
        for key, value in wanted.items()
        if key in held and getattr(held[key], "shape", None) != value.shape
    ]
    if problems:
        shown = "; ".join(problems[:3]) + (f"; {len(problems) - 3} more" if len(problems) > 3 else "")
        raise PipelineError(
            f"--resume: {last}'s weights do not fit the net this run builds ({shown}): its code changed "
            "since the run started, or the file was edited; train it anew with another --out"
        )
    problem = _check_training_state(checkpoint, module)
    if problem is not None:
        raise PipelineError(
            f"--resume: {last} is damaged ({problem}); train anew with another --out, or resume from a "
            "copy of the run"
        )


def _check_training_state(checkpoint: dict[str, Any], module: Any) -> str | None:
    """What of ``checkpoint``'s training state a resume cannot restore, None when nothing: the optimizers'
    and schedulers' states loaded into fresh ones of ``module`` (as Lightning will load them), the random
    state and the epoch. A file edited by hand (an optimizer state dropped, a random state of floats) ended
    the resume in a 30-50 line traceback from Lightning or torch."""
    epoch = checkpoint.get("epoch")
    if isinstance(epoch, bool) or not isinstance(epoch, int) or epoch < 0:
        return f"epoch {epoch!r}, not a count from 0"
    rng = checkpoint.get("crowdmpc_torch_rng")  # absent in runs from before it was kept
    expected = torch.get_rng_state()
    if rng is not None and not (
        isinstance(rng, torch.Tensor) and rng.dtype == expected.dtype and rng.shape == expected.shape
    ):
        return "crowdmpc_torch_rng is not torch's random state"
    optimizers, schedulers = module.configure_optimizers()
    # the keys without which a state restores nothing (a scheduler's load takes any dict as it is; a newer
    # torch adds keys of its own, which an older run's file lacks and which are not asked for here)
    needed = {"optimizer_states": {"state", "param_groups"}, "lr_schedulers": {"last_epoch", "base_lrs"}}
    for key, fresh in (("optimizer_states", optimizers), ("lr_schedulers", schedulers)):
        held = checkpoint.get(key)
        if not isinstance(held, list) or len(held) != len(fresh):
            holds = len(held) if isinstance(held, list) else "none" if held is None else type(held).__name__
            return f"{key}: {len(fresh)} expected, the file holds {holds}"
        for state, made in zip(held, fresh, strict=True):
            if not isinstance(state, dict) or not needed[key] <= set(state):
                return f"{key}: a state without the keys {sorted(needed[key])}"
            try:
                made.load_state_dict(state)
            except Exception as exc:  # noqa: BLE001 (torch's ValueError, KeyError, TypeError ...)
                return f"{key}: {type(exc).__name__}: {str(exc).splitlines()[0][:120] if str(exc) else ''}"
    return None


def _shape(value: Any) -> str:
    shape = getattr(value, "shape", None)
    return "x".join(map(str, shape)) if shape is not None else type(value).__name__


def epochs_to_fit(epochs: int, last: Path | None) -> int:
    """The epochs a fit goes to: ``epochs``, or for a resume (``last``: the run's last.ckpt) of a run its
    --patience had stopped (no gain in validation ADE for that many epochs) before its outputs were written,
    the epochs it trained: Lightning checks the stop at an epoch's end, and would train an epoch past it (on
    to ``epochs`` if that one gained)."""
    stopped = None if last is None else stopped_after(load_tensors(last))
    return epochs if stopped is None else min(epochs, stopped)


def check_divergence(args: argparse.Namespace, divergence: Any, best: Any) -> None:
    """PipelineError when the fit stopped on a non-finite loss (``StopOnDivergence``) before any epoch
    validated to a finite ADE: its weights are NaN, and were written, then refused on reading back as "tensor
    ... holds NaN", which named neither the cause nor the epoch. With a finite best epoch before it, that
    epoch's weights are saved as usual, and a line says why the run stopped early."""
    if divergence.epoch is None:
        return
    what = f"the training loss was {divergence.loss} in epoch {divergence.epoch}"
    score = best.best_model_score
    if score is None or not math.isfinite(float(score)):
        raise PipelineError(
            f"model {args.model!r}: training diverged: {what}, and no epoch before it validated; no weights "
            f"written. A net whose steps are NaN (a division, log or sqrt at 0, such as an agent's distance "
            f"to itself) or a learning rate too high (--lr {args.lr:g}) does this"
        )
    print_note(f"training stopped: {what}; the best epoch before it is kept")


def check_saved_predicts(model: str, weights: Path, out: Path) -> None:
    """PipelineError unless the pair just saved into a staging folder (``weights``, with its .json) loads as
    a predictor, contract check included (in eval mode and float64, where a net can break it that trained
    finite): refused only once moved into ``out``, a pair that no command can load lay there as a trained
    one's, after every epoch. The staging folder goes with the error, so nothing of it is left."""
    try:
        load_checkpoint(weights)
    except PredictorError as exc:
        why = str(exc).removeprefix(f"{weights.with_suffix('.json')}: ")
        raise PipelineError(
            f"model {model!r}: the trained net cannot be loaded as a predictor, so {weights.name} and its "
            f".json were not written into {out} (its epochs' checkpoints are): {why}"
        ) from None
