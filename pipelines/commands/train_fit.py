"""Lightning's part of ``crowdmpc train``, once every option has been checked: fit (or resume), save the best
epoch as NAME.pt + NAME.json (pipelines.commands.train_save), evaluate it and write NAME.metrics.json.
Lightning and torch are imported only when a run starts (Lightning prints a banner)."""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from pipelines.commands import replace_file
from pipelines.commands.train_save import save_best
from pipelines.errors import PipelineError, writes_named
from pipelines.plain_json import plain


def run_training(
    args: argparse.Namespace,
    net_config: Any,
    name: str,
    out: Path,
    data_files: tuple[dict, Path | None],
    settings: dict[str, Any],
    evaluated: dict[Path, list[Any]] | None = None,
) -> int:
    """Lightning's part of ``train.run``, once every option has been checked; ``evaluated``: the validation
    and test files' scenes as the evaluation reads them, by path (read by ``train_data.check_data``)."""
    from pipelines.commands.train_report import print_summary
    from predictors.models import model_kind
    from predictors.optim_config import OptimConfig

    optim = OptimConfig(
        lr=args.lr, step_size=args.step_size, loss=args.loss, variety_error=args.variety_error
    )
    _prepare_process(args.seed)
    module, best_path, elapsed, ended = _fit(args, net_config, name, out, data_files[0], settings, optim)
    metrics = out / f"{name}.metrics.json"
    # gone before the weights change: a run stopped before its new metrics are written is visibly unfinished
    # (--resume then finishes it), never new weights beside the metrics of the old ones
    metrics.unlink(missing_ok=True)
    weights, extra = save_best(args, module, name, out, best_path, optim, ended)
    top_k = 20 if model_kind(args.model).adversarial else None
    summary = _summary(args, name, out, data_files, weights, extra, elapsed, top_k, evaluated)
    text = json.dumps(plain(summary), indent=2, allow_nan=False) + "\n"  # strict JSON, as every record's
    replace_file(metrics, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
    print_summary(summary, Path(best_path).name, weights, top_k)
    return 0


def _prepare_process(seed: int) -> None:
    """One torch thread, Lightning's warnings a user can do nothing about silenced, every seed set."""
    import warnings

    import lightning as L
    import torch

    # Tiny tensors on a shared CPU: one thread is faster than torch's pool, which spin-waits for cores.
    torch.set_num_threads(1)
    warnings.filterwarnings("ignore", message=".*does not have many workers.*")
    warnings.filterwarnings("ignore", message=".*Checkpoint directory.*exists and is not empty.*")
    # fewer batches an epoch than log_every_n_steps (--limit-batches, a small file): the module logs each
    # epoch's mean train loss too (train_loss_epoch), and the CLI has no such option to act on the advice
    warnings.filterwarnings("ignore", message=".*smaller than the logging interval.*")
    # Lightning 2.6's own use of a torch pytree API that torch 2.13 deprecates: nothing a user can act on.
    warnings.filterwarnings("ignore", message=r".*isinstance\(treespec, LeafSpec\)", category=FutureWarning)
    for logger in ("lightning.pytorch.utilities.rank_zero", "lightning.fabric.utilities.rank_zero"):
        logging.getLogger(logger).addFilter(_no_advertising)
        logging.getLogger(logger).addFilter(_no_interrupt_notice)
    # its SIGTERM handler's "[rank: 0] Received SIGTERM: 15", printed above the CLI's one line: a `kill` ends
    # the run as Ctrl-C does (pipelines.loop.interrupt), and Ctrl-C prints no such line
    logging.getLogger("lightning.pytorch.trainer.connectors.signal_connector").setLevel(logging.WARNING)
    L.seed_everything(seed, workers=True, verbose=False)


def _fit(
    args: argparse.Namespace,
    net_config: Any,
    name: str,
    out: Path,
    files: dict,
    settings: dict[str, Any],
    optim: Any,
) -> tuple[Any, str, float, dict[str, Any]]:
    """Fits (or resumes) the run; returns the module holding the best epoch's weights, that checkpoint's
    path, the fit's wall time and how the fit ran (``_ended``: the batch limit, the early stop)."""
    from pipelines.commands.train_checkpoint import check_divergence
    from predictors.checkpoint import load_tensors
    from predictors.data.datamodule import TrajnetDataModule
    from predictors.training import make_module

    ckpt_dir = out / "checkpoints"
    last = ckpt_dir / "last.ckpt"
    # resolved, as train_settings.json records them: last.ckpt keeps the data module's paths, and relative
    # ones named other files to a --resume from another folder (refused as "other settings")
    train, val, test = ([Path(p).resolve() for p in files[split]] for split in ("train", "val", "test"))
    data = TrajnetDataModule(
        train, val, test, batch_size=args.batch_size, seed=args.seed, batching=args.batching
    )
    module = make_module(args.model, net_config, optim)
    if args.resume:
        from pipelines.commands.train_checkpoint import check_weights_fit

        check_weights_fit(last, module)
    trainer, best, divergence, clock = _trainer(args, out, ckpt_dir, last if args.resume else None)
    if not args.resume:
        from pipelines.commands.train_resume import SETTINGS_FILE

        out.mkdir(parents=True, exist_ok=True)
        from pipelines.plugins import code_with_plugins

        # the code too, which a resume compares with its own (train_resume.note_other_code)
        text = json.dumps({**settings, "name": name, "code": code_with_plugins()}, indent=2) + "\n"
        # in one rename: a symbolic link planted in --out is replaced, never written through
        replace_file(out / SETTINGS_FILE, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
    started = time.perf_counter()
    try:
        # a full disk fails TensorBoard's event write, whose error names no file
        with writes_named(out), _writer_thread_errors_left_to_the_fit():
            trainer.fit(module, datamodule=data, ckpt_path=str(last) if args.resume else None)
    except SystemExit as stop:
        # Lightning ends an interrupted fit with sys.exit: 1 for Ctrl-C, 0 for SIGTERM (its SIGTERMException),
        # which told a script that a killed run had trained. Both are the CLI's interrupt (130, or 143).
        raise KeyboardInterrupt from stop
    except Exception as exc:
        failed = _in_plugin(args.model, exc)
        if failed is None:
            raise
        raise PipelineError(
            f"model {args.model!r}: training failed in the net's code ({failed}): {type(exc).__name__}: "
            f"{str(exc).strip().splitlines()[0][:200] if str(exc).strip() else ''} (the contract check's "
            "synthetic batches passed; a real batch pads scenes to their largest, its absent agents masked)"
        ) from None
    # with the run's earlier parts, for a resume (their seconds came back from last.ckpt)
    elapsed = clock.before + time.perf_counter() - started
    check_divergence(args, divergence, best)

    # a file in --out: the best checkpoint saved or kept (RunCheckpoint: restored only where it is), else last
    best_path = best.best_model_path or str(last)
    state = load_tensors(Path(best_path))["state_dict"]
    module.load_state_dict(state)
    return module, best_path, elapsed, _ended(args, trainer)


def _in_plugin(model: str, exc: BaseException) -> str | None:
    """``file:line in function`` of the last frame of ``exc``'s traceback in a plugin net's module (model
    ``module:Class``), None for a shipped model or an error raised elsewhere: a net that passed the contract
    check and failed on a real batch ended train in Lightning's 75-line traceback."""
    import traceback

    from predictors.models import model_kind

    kind = model_kind(model)
    module = sys.modules.get(model.partition(":")[0]) if kind.source == "plugin" else None
    path = getattr(module, "__file__", None)
    if path is None:
        return None
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if Path(f.filename) == Path(path)]
    return None if not frames else f"{Path(path).name}:{frames[-1].lineno} in {frames[-1].name}"


def _ended(args: argparse.Namespace, trainer: Any) -> dict[str, Any]:
    """What the training record adds of how the fit ran: the batch limit that cut its epochs (``_limited``),
    and with --patience that patience and, where validation ADE's stop ended the fit, the epochs trained."""
    from lightning.pytorch.callbacks import EarlyStopping

    from pipelines.commands.train_checkpoint import StopOnDivergence

    limited = _limited(args.limit_batches, trainer)
    ended: dict[str, Any] = {} if limited is None else {"limit_batches": limited}
    if args.patience is not None:
        ended["patience"] = args.patience
        stop = next(c for c in trainer.callbacks if isinstance(c, EarlyStopping))
        diverged = next(c for c in trainer.callbacks if isinstance(c, StopOnDivergence)).epoch is not None
        # the count (restored by a resume), not stopped_epoch, which a run only sets on the fit that stops
        if stop.wait_count >= stop.patience and trainer.current_epoch < args.epochs and not diverged:
            ended["stopped_early_after"] = trainer.current_epoch  # the epochs trained
    return ended


def _limited(limit: int | None, trainer: Any) -> int | None:
    """``--limit-batches`` where it cut an epoch's training or validation batches, else None: at or above
    both counts the weights are the unlimited run's to the bit, and were recorded (and added to the zoo) as
    a quick check, their val_ade "over 100000 validation batches" of 18."""
    if limit is None:
        return None
    val = trainer.val_dataloaders
    loaders = [trainer.train_dataloader, *(val if isinstance(val, list | tuple) else [val])]
    return limit if any(loader is None or limit < len(loader) for loader in loaders) else None


@contextlib.contextmanager
def _writer_thread_errors_left_to_the_fit() -> Iterator[None]:
    """TensorBoard's event writer thread, failing (a full disk), printed its own traceback around the CLI's
    one line; it keeps the error and hands it to the fit on its next flush or close, where it ends the run
    as any write's failure does. Its print alone is dropped; every other thread's error is printed."""
    printed = threading.excepthook

    def hook(failure: threading.ExceptHookArgs) -> None:
        if not (
            type(failure.thread).__name__ == "_AsyncWriterThread"
            and type(failure.thread).__module__.startswith("tensorboard.")
            and isinstance(failure.exc_value, OSError)
        ):
            printed(failure)

    threading.excepthook = hook
    try:
        yield
    finally:
        threading.excepthook = printed


def _summary(
    args: argparse.Namespace,
    name: str,
    out: Path,
    data_files: tuple[dict, Path | None],
    weights: Path,
    extra: dict[str, Any],
    elapsed: float,
    top_k: int | None,
    evaluated: dict[Path, list[Any]] | None = None,
) -> dict[str, Any]:
    """NAME.metrics.json: the saved net's split metrics, the data it was trained on and the run's times."""
    from pipelines.commands.train_report import (
        data_record,
        epoch_times_from_csv,
        evaluate_splits,
        median_epoch_time,
    )
    from pipelines.plugins import code_with_plugins
    from predictors.checkpoint import load_checkpoint
    from predictors.hashing import sha256_file

    files, root = data_files
    protocol = "custom" if args.train is not None or args.val is not None else args.protocol
    metrics = evaluate_splits(args, load_checkpoint(weights), files, root, top_k, evaluated)
    # every version: a resumed run logs into a new one (Lightning's CSVLogger), its first epochs in the old
    epoch_times = [
        t for log_dir in sorted((out / "csv").glob("version_*")) for t in epoch_times_from_csv(log_dir)
    ]
    return {
        "name": name,
        "model": args.model,
        # what ties these metrics to their weights: `zoo add` refuses them beside other ones
        "weights_sha256": sha256_file(weights),
        # and to their config (NAME.json): an edited one with the same weights is another model
        "config_sha256": sha256_file(weights.with_suffix(".json")),
        "code": code_with_plugins(),
        "protocol": protocol,
        "training_data": data_record(files, root, protocol),
        "metrics": metrics,
        "training": {
            **extra["training"],
            "wall_time_s": round(elapsed, 1),
            "median_epoch_time_s": median_epoch_time(epoch_times),
            "threads": 1,
        },
    }


def _no_advertising(record: logging.LogRecord) -> bool:
    """Drop Lightning's "Tip: try installing litlogger / litmodels" lines (cloud services, not training)."""
    return not str(record.msg).startswith("💡 Tip")


def _no_interrupt_notice(record: logging.LogRecord) -> bool:
    """Drop Lightning's blank line and "Detected KeyboardInterrupt, attempting graceful shutdown ..." on
    Ctrl-C or `kill` during a fit: the CLI's one line says it ("crowdmpc train: interrupted")."""
    return not str(record.msg).lstrip().startswith("Detected KeyboardInterrupt")


def _trainer(args: argparse.Namespace, out: Path, ckpt_dir: Path, last: Path | None) -> tuple[Any, ...]:
    """Lightning's trainer, the callback that keeps the best checkpoint by validation ADE, the one that
    stops a diverged fit, and the run's clock; ``last``: the checkpoint a resume starts from."""
    import lightning as L
    from lightning.pytorch.callbacks import EarlyStopping, LearningRateMonitor
    from lightning.pytorch.loggers import TensorBoardLogger

    from pipelines.commands.train_checkpoint import (
        RunCheckpoint,
        StderrProgressBar,
        StopOnDivergence,
        TrainingClock,
        WholeCheckpointIO,
        WholeCSVLogger,
        epochs_to_fit,
        progress_callbacks,
    )
    from pipelines.commands.train_resume import BEST_FILENAME

    # Absolute, as the rest of the command takes them: Lightning expands a leading "~" (and reads "s3://"
    # through fsspec), so `--out '~/x'` wrote its logs and checkpoints to $HOME/x, its settings to ./~/x.
    out, ckpt_dir = out.absolute(), ckpt_dir.absolute()
    best = RunCheckpoint(
        dirpath=ckpt_dir,
        filename=BEST_FILENAME,
        monitor="val_ade",
        mode="min",
        save_last=True,
        save_top_k=1,
        enable_version_counter=False,  # the run's folder is its own (RunCheckpoint)
    )
    # validation ADE's stop (--patience): Lightning keeps its count in last.ckpt, which a resume goes on
    # counting; a NaN is StopOnDivergence's to stop and say, not a loss of patience
    patience = args.patience
    stop = None if patience is None else EarlyStopping("val_ade", patience=patience, check_finite=False)
    trainer = L.Trainer(
        max_epochs=epochs_to_fit(args.epochs, last),
        limit_train_batches=args.limit_batches,
        limit_val_batches=args.limit_batches,
        accelerator="cpu",
        devices=1,
        logger=[
            WholeCSVLogger(out, name="csv"),
            TensorBoardLogger(out, name="tensorboard", default_hp_metric=False),
        ],
        # the step schedule's rate each epoch (lr-Adam in metrics.csv and TensorBoard), as Lightning logs it
        callbacks=[
            best,
            divergence := StopOnDivergence(),
            clock := TrainingClock(),
            LearningRateMonitor(logging_interval="epoch"),
            *([] if stop is None else [stop]),
            *(shown := progress_callbacks(args.no_progress)),
        ],
        plugins=[WholeCheckpointIO()],
        deterministic=True,
        enable_progress_bar=any(isinstance(c, StderrProgressBar) for c in shown),
        enable_model_summary=False,
        log_every_n_steps=5,
    )
    return trainer, best, divergence, clock
