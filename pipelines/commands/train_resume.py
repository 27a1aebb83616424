"""``crowdmpc train --resume``: what a run was started with, and the checks that a resume continues that run
(``pipelines.commands.train`` calls them before Lightning starts). The weights, optimiser and schedule come
back from last.ckpt whatever the command line says, so a resume asking for other settings, or a last.ckpt of
another model, is refused in one line rather than trained on and recorded wrongly."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Any, Final

from pipelines.errors import PipelineError, print_note
from predictors.checkpoint import check_name, load_tensors
from predictors.errors import DuplicateKey, PredictorError, short_key, unique_keys

# What fixes a training run: --resume continues it with these, and only --epochs may change.
SETTINGS_FILE = "train_settings.json"
# Every key a run's settings file has held, in any version (run_settings, train_data.data_settings, and the
# code train_fit adds): a key besides them is a misspelt edit, which a resume ignored and then refused the run
# by the default that stood in for it ("seed: checkpoint 5, now 0").
SETTINGS_KEYS: Final[tuple[str, ...]] = (
    *("name", "model", "net_config", "lr", "step_size", "loss", "variety_error", "seed", "batch_size"),
    *("batching", "limit_batches", "patience", "epochs", "files", "data", "data_dir", "data_sha256", "code"),
)
# The paths of checkpoints a Lightning ModelCheckpoint's state holds, besides its best_k_models' keys.
_PATH_KEYS = ("best_model_path", "last_model_path", "kth_best_model_path")
# The best checkpoints' names: Lightning writes "{epoch:03d}" as epoch=001 (train_fit's callback).
BEST_FILENAME = "best-{epoch:03d}-{val_ade:.4f}"
BEST_PREFIX = "best-epoch="
_LOSSES = ("gaussian", "l2")  # predictors.optim_config.LOSSES, without importing torch
LOCK_FILE = ".train.lock"
# What a resume names by a noun alone (say_taken), rather than as an option and its value
_NOUNS: Final[tuple[str, ...]] = ("net config", "data files")
# Recorded but not compared on a resume: the files a data directory gives are (train_data.data_settings),
# the epochs in all, which a resume may change (train_epochs), and the files' hashes, which
# train_data.check_resumed_data compares with a message of their own
_NOT_COMPARED: Final[tuple[str, ...]] = ("data_dir", "epochs", "data_sha256")
# settings a run's file holds since they were added, as a run that predates them ran: without early stop,
# a GAN on the distance variety loss
_ADDED_LATER: Final[dict[str, Any]] = {"patience": None, "variety_error": "distance"}
# The options a resume takes from its run when they are not typed, and their defaults for a new run: the
# parser's defaults are None, so that an option typed can be told from one left out (--batch-size 8 typed on
# the resume of a run at 2 is refused; left out, the run's 2 goes on). Types as the run records them.
RUN_OPTIONS: Final[dict[str, Any]] = {
    "lr": 1e-3,
    "step_size": 10,
    "batch_size": 8,
    "batching": "shuffled",
    "seed": 0,
    "patience": None,  # train every epoch (no early stop)
    "variety_error": "distance",
}
_RECORDED_TYPES: Final[dict[str, tuple[type, ...]]] = {
    "lr": (float, int),
    "step_size": (int,),
    "batch_size": (int,),
    "batching": (str,),
    "seed": (int,),
    "limit_batches": (int,),
    "patience": (int,),
    "variety_error": (str,),
}


def one_run_at_a_time(out: Path):
    """Hold ``out``'s lock (a hidden file made with the folder; a second train is refused) while a run
    trains: the check that --out holds no run (no last.ckpt until the first epoch ends) let a second train
    started meanwhile train into the same folder, which ended with one run's settings beside the other's
    last.ckpt. A run that fails leaves no folder it made (--out and the parents it needed), nor its lock in
    an --out it found (a sweep --out refused the empty folder for it)."""
    from predictors.locking import locked_undone_on_failure

    def refuse() -> None:
        raise PipelineError(
            f"another crowdmpc train is writing to {out}; wait for it or choose another --out"
        )

    return locked_undone_on_failure(out / LOCK_FILE, "lock the training run", waiting=refuse)


def run_settings(args: argparse.Namespace, net_config: Any, name: str, files: dict[str, list[Path]]) -> dict:
    from predictors.models import model_kind

    return {
        "name": name,
        "model": args.model,
        "net_config": model_kind(args.model).config_dict(net_config),
        "lr": args.lr,
        "step_size": args.step_size,
        "loss": args.loss,
        "variety_error": args.variety_error,
        "seed": args.seed,
        "batch_size": args.batch_size,
        "batching": args.batching,
        "limit_batches": args.limit_batches,
        "patience": args.patience,
        "epochs": args.epochs,  # the one setting a resume may change (train_epochs)
        "files": {split: [str(p.resolve()) for p in paths] for split, paths in files.items()},
    }


def read_run_settings(out: Path) -> dict[str, Any] | None:
    """The settings the run in ``out`` was started with (its train_settings.json); None when it has none (a
    run from before the file was kept); PipelineError when the file is no readable JSON object, which the
    run wrote: it was damaged. Read once by a resume, whose loss, checks and note on the code all take it
    (each read it again)."""
    path = out / SETTINGS_FILE
    if not path.is_file():
        return None
    try:
        recorded = json.loads(path.read_text(encoding="utf-8"), object_pairs_hook=unique_keys)
    except DuplicateKey as exc:
        raise PipelineError(f"--resume: {path}: {exc}") from None
    except (OSError, ValueError, RecursionError) as exc:
        raise PipelineError(f"--resume: {path} is not readable JSON ({exc})") from None
    if not isinstance(recorded, dict):
        raise PipelineError(f"--resume: {path} is not a JSON object of settings; the run's file is damaged")
    unknown = [key for key in recorded if key not in SETTINGS_KEYS]
    if unknown:
        raise PipelineError(
            f"--resume: {path} holds the key {short_key(unknown[0])}, which crowdmpc train never writes "
            f"(edited?); the file holds only {', '.join(SETTINGS_KEYS)}"
        )
    return recorded


def checkpoint_record(out: Path) -> dict[str, Any] | None:
    """What the last.ckpt of the run in ``out`` says it was trained with (``checkpoint_settings``, the values
    it holds): the settings a resume goes on with for a run from before its settings file was kept; None
    where it cannot be read (``check_last_checkpoint`` then says why)."""
    try:
        checkpoint = load_tensors(out / "checkpoints" / "last.ckpt")
        hyper, data = checkpoint["hyper_parameters"], checkpoint.get("datamodule_hyper_parameters")
        held = checkpoint_settings(hyper, data)
        stop = early_stopping_state(checkpoint)
        held["patience"] = None if stop is None else stop.get("patience")
    except Exception:
        return None
    return {key: value for key, value in held.items() if value is not None}


def take_run_options(args: argparse.Namespace, recorded: dict[str, Any] | None) -> list[str]:
    """Each of ``RUN_OPTIONS`` and --limit-batches the command line left out: on a resume the run's
    (``recorded``: its settings file, else ``checkpoint_record``), else the default. Returns those taken
    from the run that differ from the default (which a resume names). A recorded value of the wrong type (a
    damaged file) is not taken: the default then differs from the run's, and ``check_resumed_settings``
    refuses the resume naming both."""
    taken = []
    run = recorded if args.resume and recorded is not None else {}
    for key in (*RUN_OPTIONS, "limit_batches"):
        if getattr(args, key) is not None:
            continue
        value = run.get(key)
        if isinstance(value, _RECORDED_TYPES[key]) and not isinstance(value, bool):
            setattr(args, key, value)
            if value != RUN_OPTIONS.get(key):
                taken.append(key)
        else:
            setattr(args, key, RUN_OPTIONS.get(key))
    return taken


def say_taken(
    out: Path, args: argparse.Namespace, taken: list[str], net_taken: bool, data_taken: list[str]
) -> None:
    """Name on stderr what a resume took from its run (``take_run_options``' ``taken``, its net config when
    ``net_taken``, and ``train_data.take_run_data``'s ``data_taken``): values the command line did not
    give, which the run will train with."""
    shown = [f"{key} {getattr(args, key)}" for key in taken] + ["net config"] * net_taken + data_taken
    if shown:
        # "the run's batch_size 2, its net config": a name after the first values reads as the run's too
        shown = [shown[0]] + [f"its {s}" if s in _NOUNS else s for s in shown[1:]]
        print_note(f"--resume: {out} goes on with the run's {', '.join(shown)}")


def recorded_loss(recorded: dict[str, Any] | None, last: Path) -> str | None:
    """The loss the run was started with: its settings' (``read_run_settings``), else ``last``'s (runs
    from before that file); None when neither says (the checks of the resume then say what is wrong with
    them). A resume that types no --loss continues with it: a run started before the default followed the
    net's head recorded "gaussian" for a point head too, which trained on L2 and is still refused when
    typed."""
    loss = recorded.get("loss") if recorded is not None else None
    if loss in _LOSSES:
        return str(loss)
    try:
        hyper = load_tensors(last).get("hyper_parameters")
        loss = hyper["optim_config"]["loss"]
    except Exception:  # refused, with why, by check_last_checkpoint
        return None
    return str(loss) if loss in _LOSSES else None


def check_resumed_settings(
    out: Path, recorded: dict[str, Any] | None, settings: dict[str, Any], *, name_given: bool
) -> str:
    """The run's name; PipelineError when the command asks for other settings than the run in ``out`` was
    started with (``recorded``, ``read_run_settings``): the weights, optimiser and schedule resume from
    last.ckpt whatever the command says, so the written NAME.json would record settings that never trained
    them. Runs from before the settings were kept have none, and are not checked."""
    if recorded is None:
        return str(settings["name"])
    if not name_given:  # the default name follows the options, which are checked below
        settings = {**settings, "name": recorded.get("name", settings["name"])}
        try:  # it names files in --out: '../x' wrote beside it
            check_name(settings["name"], "its name")
        except PredictorError as exc:
            raise PipelineError(f"--resume: {out / SETTINGS_FILE}: {exc}; the file is damaged") from None
    recorded = {**_ADDED_LATER, **recorded}  # a run from before an option was kept ran without it
    differ = [k for k in settings if k in recorded and k not in _NOT_COMPARED and recorded[k] != settings[k]]
    if differ:
        shown = "; ".join(f"{k}: {_compared('run', recorded[k], settings[k])}" for k in differ)
        raise PipelineError(
            f"--resume: {out} was started with other settings ({shown}); resume with the run's settings "
            "(only --epochs may change) or start a new run with another --out"
        )
    return str(settings["name"])


def note_other_code(out: Path, recorded: dict[str, Any] | None) -> None:
    """Say so when the run in ``out`` was started (``recorded``: its settings) by other code than this
    resume's (another commit, other libraries; "dirty" alone cannot be compared), or by code that recorded
    none: the epochs so far were trained by it, the next by this code, and NAME.metrics.json names this code
    only. Not refused, as a sweep's resume is not: a change that leaves training alone (documentation, a
    benchmark) is common. No settings (a run from before they were kept): no note."""
    from pipelines.plugins import code_with_plugins
    from pipelines.version import code_changes

    if recorded is None:
        return
    shown = code_changes([recorded.get("code")], code_with_plugins())
    if shown:
        print_note(
            f"note: --resume: {out} was started by other code ({shown}); its epochs so far were trained by "
            "that code and the next by this one, and the metrics file will name this code only"
        )


def check_last_checkpoint(last: Path, settings: dict[str, Any]) -> int | None:
    """The epochs ``last`` has finished (None: it does not say); PipelineError unless it is a Lightning
    checkpoint (read as weights only, as Lightning reads it) trained with the settings asked for
    (``checkpoint_settings``): a cut, foreign or other-model file otherwise fails inside Lightning with a
    traceback, and other settings would be recorded for weights they never trained. The checkpoint is the
    authority even when the run's settings file is gone or damaged."""
    try:
        checkpoint = load_tensors(last)
    except Exception as exc:  # torch raises RuntimeError, UnpicklingError, EOFError ... for a bad file
        raise PipelineError(
            f"--resume: {last} is not a readable Lightning checkpoint (damaged, or not written by `crowdmpc "
            f"train`; {_first_sentence(exc)})"
        ) from None
    hyper = checkpoint.get("hyper_parameters") if isinstance(checkpoint, dict) else None
    if not isinstance(hyper, dict) or "state_dict" not in checkpoint:
        raise PipelineError(f"--resume: {last} is not a crowdmpc training checkpoint (no hyper-parameters)")
    held = checkpoint_settings(hyper, checkpoint.get("datamodule_hyper_parameters"))
    asked = {**settings, "files": _resolved(settings["files"])}
    differ = [k for k, v in held.items() if v is not None and v != asked.get(k)]
    if differ:
        shown = "; ".join(f"{k}: {_compared('checkpoint', held[k], asked.get(k))}" for k in differ)
        what = "another model" if {"model", "net_config"} & set(differ) else "other settings"
        raise PipelineError(
            f"--resume: {last} was trained with {what} ({shown}); resume with the run's settings (only "
            "--epochs may change)"
        )
    # last.ckpt is written as each epoch ends, after its validation (train_checkpoint.RunCheckpoint), and
    # Lightning counts its "epoch" from 0: it has finished epoch + 1
    epoch = checkpoint.get("epoch")
    done = epoch + 1 if isinstance(epoch, int) and not isinstance(epoch, bool) and epoch >= 0 else None
    check_kept_checkpoints(checkpoint, last, done)
    return done


def _first_sentence(exc: Exception) -> str:
    """``exc``'s class and the first sentence of its message: torch's run on for lines (how to load an
    untrusted file, what a miniz error may mean), which cut at a length ended mid-sentence. A first
    sentence too long to show is left out rather than cut."""
    line = (str(exc).strip().splitlines() or [""])[0]
    sentence = re.split(r"(?<=[.!?])\s", line, maxsplit=1)[0].strip()
    return f"{type(exc).__name__}: {sentence}" if sentence and len(sentence) <= 160 else type(exc).__name__


def check_kept_checkpoints(checkpoint: dict[str, Any], last: Path, done: int | None) -> None:
    """PipelineError unless every best checkpoint ``last`` says the run keeps is in its folder, but in the
    one state Lightning leaves itself: the next epoch's new best saved and the one before removed, last.ckpt
    not yet rewritten (a kill -9 between the two; ``RunCheckpoint`` forgets the removed one and trains that
    epoch again). A best missing otherwise (a run moved or copied without it) would make a worse epoch the
    run's NAME.pt, which no run that was never stopped would have given."""
    missing = sorted(
        {name for name in map(_file_name, kept_checkpoints(checkpoint)) if not (last.parent / name).is_file()}
    )
    if not missing or (done is not None and any(last.parent.glob(f"{BEST_PREFIX}{done:03d}-*.ckpt"))):
        return
    raise PipelineError(
        f"--resume: {last} names the run's checkpoint {missing[0]}, which is not in {last.parent}; put it "
        "back there or start a new run with another --out"
    )


def kept_checkpoints(checkpoint: dict[str, Any]) -> list[str]:
    """The paths of the best checkpoints the ModelCheckpoint states in a Lightning ``checkpoint`` keep."""
    states = checkpoint.get("callbacks")
    paths: list[Any] = []
    for key, state in states.items() if isinstance(states, dict) else ():
        if str(key).startswith("ModelCheckpoint") and isinstance(state, dict):
            best_k = state.get("best_k_models")
            paths += [state.get("best_model_path"), *(best_k if isinstance(best_k, dict) else ())]
    return [path for path in paths if isinstance(path, str) and path]


def _file_name(path: str) -> str:
    return Path(path).name


def relocated(state: dict[str, Any], dirpath: str) -> dict[str, Any]:
    """A ModelCheckpoint's ``state`` with every path it keeps moved into ``dirpath``, the run's checkpoint
    folder now: Lightning stores them absolute and restores them only when that folder has not moved, so a
    moved run forgot its best score and wrote last-v1.ckpt, and still read its best weights from the old
    folder. The run's checkpoints are all in that one folder, so a file's name finds it (one not there is
    refused by ``check_kept_checkpoints``, or forgotten by ``RunCheckpoint`` in the state a kill leaves)."""

    def here(path: Any) -> Any:
        return str(Path(dirpath) / Path(path).name) if isinstance(path, str) and path else path

    moved = {key: here(state[key]) for key in _PATH_KEYS if key in state}
    if isinstance(state.get("best_k_models"), dict):
        moved["best_k_models"] = {here(path): score for path, score in state["best_k_models"].items()}
    return {**state, **moved, "dirpath": dirpath}


def early_stopping_state(checkpoint: dict[str, Any]) -> dict[str, Any] | None:
    """The state a Lightning ``checkpoint`` keeps of ``--patience``'s EarlyStopping (``wait_count``,
    ``patience``, ``best_score``, ``stopped_epoch``); None for a run without it."""
    states = checkpoint.get("callbacks")
    for key, state in states.items() if isinstance(states, dict) else ():
        if str(key).startswith("EarlyStopping") and isinstance(state, dict):
            return state
    return None


def checkpoint_settings(hyper: dict[str, Any], data: Any) -> dict[str, Any]:
    """``run_settings``' keys as a training checkpoint holds them (the modules' and the data module's
    hyper-parameters; None where it holds none, a checkpoint of an older layout)."""
    held = hyper.get("optim_config")
    optim: dict[str, Any] = held if isinstance(held, dict) else {}
    data = data if isinstance(data, dict) else {}
    files = data.get("files")  # before the data module saved its constructor's names
    if files is None and "train_files" in data:
        files = {split: data.get(f"{split}_files") for split in ("train", "val", "test")}
    return {
        "model": hyper.get("model", "social_gan" if "discriminator_config" in hyper else None),
        "net_config": hyper.get("net_config"),
        **{k: optim.get(k) for k in ("lr", "step_size", "loss")},
        "variety_error": optim.get("variety_error", "distance") if optim else None,  # as _ADDED_LATER
        "seed": data.get("seed"),
        "batch_size": data.get("batch_size"),
        # a data module from before --batching batched as "shuffled" does
        "batching": data.get("batching", "shuffled") if data else None,
        "files": _resolved(files) if isinstance(files, dict) else None,
    }


def _resolved(files: dict[str, Any]) -> dict[str, list[str]]:
    return {split: [str(Path(p).resolve()) for p in paths] for split, paths in files.items()}


def _short(value: Any) -> str:
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= 80 else text[:77] + "..."


def _compared(source: str, run: Any, now: Any) -> str:
    """A setting's two values as a refusal shows them ("run 0.001, now 0.05"); two dicts (a net config,
    the files) by the keys they differ in, which a whole config cut at 80 characters hid (a net's
    hidden_dim comes after ten keys)."""
    if isinstance(run, dict) and isinstance(now, dict):
        keys = [k for k in {**run, **now} if run.get(k, ...) != now.get(k, ...)]
        run, now = ({k: _file_names(v[k], (run, now), k) for k in keys if k in v} for v in (run, now))
    return f"{source} {_short(run)}, now {_short(now)}"


def _file_names(value: Any, both: tuple[dict, dict], key: str) -> Any:
    """A split's files by their names where the names tell the run's from the command's (the folders,
    shown whole, pushed the names past the 80 characters shown); any other value as it is."""
    names = []
    for side in both:
        held = side.get(key)
        if not isinstance(held, list) or not all(isinstance(p, str) for p in held):
            return value
        names.append([Path(p).name for p in held])
    return [Path(p).name for p in value] if names[0] != names[1] else value
