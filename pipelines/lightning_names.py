"""Lightning's names for what ``crowdmpc train`` sets, for the one-line error of an option a Lightning user
types: `crowdmpc train --max-epochs 3` (or LightningCLI's ``--trainer.max_epochs=3``) was argparse's bare
"unrecognized arguments", with no pointer to ``--epochs``."""

from __future__ import annotations

from collections.abc import Iterable

# Trainer arguments, and the usual names of a LightningModule's and DataModule's, that crowdmpc train sets
# under a name of its own (pipelines/commands/train.py, train_fit.py's Trainer)
EQUIVALENTS = {
    "max_epochs": "--epochs",
    "limit_train_batches": "--limit-batches (train and validation alike)",
    "limit_val_batches": "--limit-batches (train and validation alike)",
    "fast_dev_run": "--epochs 1 --limit-batches 1",
    "enable_progress_bar": "--no-progress, to turn it off",
    "default_root_dir": "--out",
    "ckpt_path": "--resume (from --out's last.ckpt)",
    "seed_everything": "--seed",
    "learning_rate": "--lr",
    "batch_size": "--batch-size",
}
# set by crowdmpc train itself on purpose (the CPU, one thread, deterministic): no option for them
ABSENT = ("accelerator", "devices", "gpus", "num_nodes", "strategy", "precision")
ABSENT_WHY = (
    "crowdmpc train has none: it trains on the CPU in one thread, deterministically (a seed gives the same "
    "weights); another accelerator or precision takes a lightning.Trainer of your own (docs/extending.md)"
)


def lightning_hint(words: Iterable[str], own: Iterable[str]) -> str:
    """The hint for the Lightning names among ``words`` (a command line), " (...)", or "" where none is one.

    ``own``: the command's option strings, never hinted (``--batch-size`` is crowdmpc's own). A name is read
    as Lightning writes it or as a flag (``--max-epochs``, ``--max_epochs=3``, ``--trainer.max_epochs``)."""
    mine, hints, absent = set(own), [], []
    for word in words:
        typed = word.split("=", 1)[0]
        if not typed.startswith("--") or typed in mine:
            continue
        name = typed[2:].rsplit(".", 1)[-1].replace("-", "_").lower()
        if name in EQUIVALENTS:
            hint = f"{typed} is Lightning's {name}: crowdmpc train's is {EQUIVALENTS[name]}"
            hints += [] if hint in hints else [hint]
        elif name in ABSENT and typed not in absent:
            absent.append(typed)
    if absent:
        hints.append(f"{', '.join(absent)}: {ABSENT_WHY}")
    return f" ({'; '.join(hints)})" if hints else ""
