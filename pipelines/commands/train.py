"""``crowdmpc train``: train a predictor net of any registered model kind (``predictors.models``: Social-LSTM,
the vanilla LSTM, the Social-GAN-like model, Social-GRU, social attention, entry points, plugins) with
Lightning."""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path
from typing import Any

from pipelines.commands import check_outside_the_zoos, check_writable
from pipelines.commands.output_paths import output_arg
from pipelines.commands.train_data import (
    DATASET_SUFFIX,
    DEFAULT_DATASET,
    check_data,
    check_resumed_data,
    data_options,
    data_settings,
    note_shared_data,
    protocol_options,
    resolve_files,
    take_run_data,
)
from pipelines.commands.train_epochs import DEFAULT_EPOCHS, check_more_epochs, record_epochs, take_run_epochs
from pipelines.commands.train_folder import check_run_folder
from pipelines.commands.train_net import (
    check_variety_error,
    check_variety_error_applies,
    loss_options,
    net_config_of,
    resumed_net_config,
    training_loss,
    trains_point_head,
)
from pipelines.commands.train_resume import (
    SETTINGS_FILE,
    check_last_checkpoint,
    check_resumed_settings,
    checkpoint_record,
    note_other_code,
    one_run_at_a_time,
    read_run_settings,
    recorded_loss,
    run_settings,
    say_taken,
    take_run_options,
)
from pipelines.errors import PipelineError
from predictors.errors import PredictorError

# Adam's learning rate: these nets train at 1e-3; far above any useful rate, and far below float32's
# overflow (~3.4e38), where a huge --lr used to end inside Adam with a traceback.
MAX_LR = 10.0

EPILOG = """examples:
  crowdmpc train --model social_lstm --data-dir ../shared/data --epochs 25
  crowdmpc train --model social_lstm --pooling soft --data-dir ../shared/data --out runs/train/sl_soft
  crowdmpc train --model social_lstm --data-dir ../shared/data --out runs/train/sl_soft --resume
  crowdmpc train --model social_lstm --data-dir ../shared/data --batching by_size   # less padding
  crowdmpc train --model social_lstm --train data/synth/train.ndjson --val data/synth/val.ndjson \\
      --test data/synth/test.ndjson --name my_lstm_synth    # files from `crowdmpc data synth --out ...`
  crowdmpc train --model social_attention --net-config '{"heads": 2}' --data-dir ../shared/data
  crowdmpc --plugin my_predictor:MyNet train --model my_predictor:MyNet --data-dir ../shared/data

--model takes every registered model kind: the shipped ones, installed entry points (group
"crowdmpc.predictors") and plugins (crowdmpc --plugin module:NetClass, or $CROWDMPC_PLUGINS). --net-config
sets hyper-parameters of the kind's config (a JSON object; unknown keys and bad values are refused);
--pooling and --hidden-dim are short for two of them, for the kinds whose config has them.

Writes into --out: checkpoints/ (Lightning: best on val ADE, and last.ckpt for --resume), csv/ and
tensorboard/ logs, train_settings.json, and at the end NAME.pt + NAME.json (state_dict + config) with
NAME.metrics.json (TrajNet++ val/test metrics of the best epoch; a sampling net's top-20 drawn as `crowdmpc
evaluate --top-k 20` draws it, whatever --seed). `crowdmpc zoo add OUT/NAME.pt` puts the pair into the user
zoo. --resume continues the run as if it had not stopped (same order, rotations and noise): an option left out
takes the run's setting (its data files, protocol, dataset and data directory too, unless a data option is
typed; --out names the run), one typed must be the run's, and only --epochs may change, to no fewer than the
epochs trained (that count only finishes a run that stopped before its metrics); a data file whose content
changed since the run started is refused. --val and --test files are read as `crowdmpc evaluate` reads them
(the last 21 steps of a longer scene), the validation of each epoch that picks the best one too; --train
files' scenes must have exactly 21 steps (training windows). All are read before training starts: a TrajNet++
test/ file without ground truth is refused then, not after training. A --test file with the content of a
--train or --val file is noted. It trains on the CPU in one thread (deterministic: a seed gives the same
weights); another accelerator, precision or your own callbacks and loggers take a lightning.Trainer of your
own (docs/extending.md). A second train into an --out where one is running is refused (its lock:
OUT/.train.lock), and so is an --out folder holding files but no training run (no train_settings.json): choose
an empty or new one.
"""


# Each option so marked has no parser default: left out on --resume, the run's value goes on
# (train_resume.RUN_OPTIONS holds the defaults of a new run).
RESUMED = "; with --resume, the run's"


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "train",
        help="train a learned predictor (Social-LSTM, Social-GRU, attention, ..., or a plugin's net)",
        description="Train a predictor on TrajNet++ scenes with Lightning: progress bar, CSV and TensorBoard "
        "logs, best checkpoint on validation ADE, resumable, seeded.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _net_options(parser)
    data_options(parser)
    _optimisation_options(parser)
    parser.add_argument(
        "--hidden-dim",
        type=int,
        default=None,
        help="hidden size, for kinds whose config has hidden_dim" + RESUMED,
    )
    parser.add_argument("--name", default=None, help="checkpoint name (default e.g. social_lstm_soft_eth)")
    parser.add_argument(
        "--out", type=output_arg, default=None, help="run directory (default runs/train/NAME)"
    )
    parser.add_argument("--resume", action="store_true", help="continue the run in --out from last.ckpt")
    parser.add_argument(
        "--seed",
        type=int,
        default=None,
        help="seed of weights, shuffling, augmentation (default 0)" + RESUMED,
    )
    parser.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar (on a terminal) nor line an epoch (elsewhere)",
    )
    parser.set_defaults(func=run)


def _net_options(parser: argparse.ArgumentParser) -> None:
    """What to train: the model kind and its hyper-parameters."""
    parser.add_argument(
        "--model",
        required=True,
        type=model_name,
        metavar="KIND",
        help="model kind: social_lstm, vanilla_lstm, social_gan, social_gru, social_attention, an entry "
        "point's name, or a plugin's module:NetClass",
    )
    parser.add_argument(
        "--pooling",
        default=None,
        help="social pooling: grid (hard, TrajNet++) or soft (bilinear, differentiable), or none where the "
        "kind allows it (social_gru: a plain GRU); default grid for social_lstm, soft for social_gan and "
        "social_gru; not for vanilla_lstm, and only for kinds whose config has a pooling; a pooling other "
        "than the kind's default is in the default --name (social_lstm_soft_eth); with --resume, the run's",
    )
    parser.add_argument(
        "--net-config",
        default=None,
        metavar="JSON",
        help="hyper-parameters over the kind's defaults, a JSON object, e.g. '{\"hidden_dim\": 64}'; with "
        "--resume, over the run's config (each one left out is the run's)",
    )


def _optimisation_options(parser: argparse.ArgumentParser) -> None:
    """How long and how fast: epochs, batches, learning rate and its decay, the loss (``train_net``)."""
    parser.add_argument(
        "--epochs",
        type=int,
        default=None,
        help=f"training epochs in all (default {DEFAULT_EPOCHS}; with --resume, the run's last --epochs)",
    )
    parser.add_argument(
        "--batch-size", type=int, default=None, help="scenes per batch (default 8, as TrajNet++)" + RESUMED
    )
    parser.add_argument(
        "--batching",
        choices=("shuffled", "by_size"),  # predictors.data.batching.BATCHINGS, without importing torch
        default=None,
        help="how an epoch's shuffled scenes are cut into batches: shuffled (as they come, as TrajNet++) or "
        "by_size (buckets of scenes of similar agent counts: less padding, faster epochs, other weights; "
        "recorded in the checkpoint) (default shuffled)" + RESUMED,
    )
    parser.add_argument(
        "--limit-batches",
        type=int,
        default=None,
        metavar="N",
        help="train and validate on the first N batches of each epoch (Lightning's limit_train_batches and "
        "limit_val_batches): a quick check that a net trains; the checkpoint records it where it cut an "
        "epoch's batches (default: all)" + RESUMED,
    )
    parser.add_argument(
        "--patience",
        type=int,
        default=None,
        metavar="N",
        help="stop once validation ADE has not improved for N epochs (Lightning's EarlyStopping; the best "
        "epoch's weights are saved, as always; default: every epoch of --epochs)" + RESUMED,
    )
    parser.add_argument(
        "--lr",
        type=float,
        default=None,
        help=f"Adam learning rate, in (0, {MAX_LR:g}] (default 1e-3)" + RESUMED,
    )
    parser.add_argument(
        "--step-size",
        type=int,
        default=None,
        help="epochs per 10x learning-rate decay (default 10)" + RESUMED,
    )
    loss_options(parser, RESUMED)


def model_name(text: str) -> str:
    """An argparse type: a registered model kind (plugins given before the command are registered by then)."""
    from pipelines.loop.spec import registered_controller_plugins
    from predictors.models import model_kind

    try:
        return model_kind(text).name
    except PredictorError as exc:
        message = str(exc)
        if text in registered_controller_plugins():  # --plugin took its class for a controller
            message = (
                f"model {text!r} is registered as a controller (a class with reset and act), not a predictor "
                "net (an nn.Module with encode and decode_step, docs/extending.md): train takes a net"
            )
        raise argparse.ArgumentTypeError(message) from None


def default_name(model: str, pooling: str | None, dataset: str, explicit_files: bool) -> str:
    """``social_lstm_soft_eth`` and the like: a pooling other than the kind's own is named (a plain GRU,
    ``--pooling none``, was called social_gru_eth); a plugin's ``module:MyNet`` gives ``my_net_eth``."""
    from predictors.models import model_kind

    suffix = "custom" if explicit_files else DATASET_SUFFIX[dataset]
    own = None if pooling is None else getattr(model_kind(model).config(), "pooling", None)
    variant = f"_{pooling}" if own is not None and pooling != own else ""
    stem = model.rpartition(":")[2]
    if stem != model:  # a class name: MyNet -> my_net
        stem = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", stem).lower()
    stem = re.sub(r"[^A-Za-z0-9_.-]", "_", stem).lstrip("_.-") or "model"
    return f"{stem[:48]}{variant}_{suffix}"


def _check_numbers(args: argparse.Namespace) -> None:
    """Every number of the command line (and --variety-error, which a resume may take from a damaged file),
    before Lightning is imported (it prints a banner) or a file read."""
    if args.lr is not None and not (math.isfinite(args.lr) and 0 < args.lr <= MAX_LR):
        raise PipelineError(f"--lr must be a finite number in (0, {MAX_LR:g}], got {args.lr}")
    # Upper bounds far above any sensible run, so that a typo cannot ask for days or for all the memory:
    # the zoo refuses hidden sizes over 4096 (predictors/nets), and ETH/hotel has ~2000 training scenes.
    for option, value, high in (
        ("--epochs", args.epochs, 100_000),
        ("--batch-size", args.batch_size, 65_536),
        ("--step-size", args.step_size, 100_000),
        ("--hidden-dim", args.hidden_dim, 4096),
        ("--limit-batches", args.limit_batches, 1_000_000),
        ("--patience", args.patience, 100_000),
    ):
        if value is not None and not 1 <= value <= high:
            raise PipelineError(f"{option} must be in 1..{high}, got {value}")
    if args.seed is not None and not 0 <= args.seed < 2**32:  # Lightning makes one outside numpy's range 0
        raise PipelineError(f"--seed must be in 0..{2**32 - 1}, got {args.seed}")
    check_variety_error(args)


def run(args: argparse.Namespace) -> int:
    from predictors.checkpoint import check_name

    _check_numbers(args)  # those typed; the ones a resume takes from its run are checked again below
    pooling, net_config = net_config_of(args)
    check_variety_error_applies(args)  # as typed: a resume takes the run's (below), recorded for every kind
    explicit = args.train is not None or args.val is not None
    protocol_options(args, explicit)
    # `--name ''` (an unset shell variable) is refused by check_name, not taken for no name
    name = (
        args.name
        if args.name is not None
        else default_name(args.model, pooling, args.dataset or DEFAULT_DATASET, explicit)
    )
    check_name(name, "--name")  # NAME becomes file names (OUT/NAME.pt) and the zoo name
    out = args.out or Path("runs") / "train" / name
    # A resume goes on with the run's settings wherever the command line leaves one out (read once: a run's
    # settings never change once it exists); the checks below refuse one typed otherwise.
    recorded = read_run_settings(out) if args.resume else None
    started = checkpoint_record(out) if args.resume and recorded is None else recorded
    taken = take_run_options(args, started) + take_run_epochs(args, out, started)
    data_taken = take_run_data(args, recorded, out)
    pooling, net_config, net_taken = resumed_net_config(args, started, pooling, net_config)
    try:
        _check_numbers(args)
    except PipelineError as exc:  # "--seed must be ...": of a value the command line never typed
        source = out / SETTINGS_FILE if recorded is not None else out / "checkpoints" / "last.ckpt"
        raise PipelineError(f"--resume: {exc}, taken from {source}; the file is damaged") from None
    # before the data: a --loss the net does not train on is refused before files are read or prepared
    loss_typed = args.loss is not None
    args.loss = training_loss(args, net_config)
    ckpt_dir = out / "checkpoints"
    check_outside_the_zoos(out, "--out", "the training run")
    # `--out .` in a clone: Lightning's checkpoints/ is the shipped zoo's folder
    check_outside_the_zoos(ckpt_dir, f"--out {out}: its folder", "the training run")
    check_writable(out, "--out", directory=True)
    check_run_folder(out, args.resume)
    files, root = resolve_files(args)
    evaluated = check_data(files, progress=False if args.no_progress else None)

    settings = {**run_settings(args, net_config, name, files), **data_settings(args, files)}
    from pipelines.commands.train_fit import run_training

    with one_run_at_a_time(out):  # under the lock: a train into --out may have started or ended since
        name = _check_out(args, out, settings, net_config, loss_typed, recorded)
        if not args.resume:  # said when the run starts, not above a refusal's one line
            note_shared_data(files, settings["data_sha256"])
        say_taken(out, args, taken, net_taken, data_taken)
        if args.resume and recorded is not None:
            record_epochs(out, recorded, args.epochs)
        return run_training(args, net_config, name, out, (files, root), settings, evaluated)


def _check_out(
    args: argparse.Namespace,
    out: Path,
    settings: dict,
    net_config: Any,
    loss_typed: bool,
    recorded: dict[str, Any] | None,
) -> str:
    """The run's name, once what --out holds is checked: no run unless --resume, else one it continues
    (``recorded``: its settings file, ``train_resume.read_run_settings``)."""

    last = out / "checkpoints" / "last.ckpt"
    if not args.resume and last.is_file():
        raise PipelineError(f"{out} already holds a training run; pass --resume to continue it or pick --out")
    if not args.resume:
        return str(settings["name"])
    loss = recorded_loss(recorded, last)
    # the run's own when none is typed: runs before this default recorded "gaussian" for point heads too,
    # which trained on L2, so for a point head that record is the "l2" typed, not another setting
    if not loss_typed or (loss == "gaussian" and trains_point_head(args, net_config)):
        settings["loss"] = args.loss = loss or args.loss
    name = check_resumed_settings(out, recorded, settings, name_given=args.name is not None)
    check_resumed_data(out, recorded, settings["data_sha256"])
    done = check_last_checkpoint(last, settings)
    check_more_epochs(out, args.epochs, done, out / f"{name}.metrics.json")
    note_other_code(out, recorded)
    return name
