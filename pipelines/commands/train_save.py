"""The best epoch of a ``crowdmpc train`` saved as OUT/NAME.pt + NAME.json with the training record they
carry, each in one rename from a staging folder in OUT (pipelines.commands.train_fit); a kill's leftover
staging folders are removed first. torch is imported only when a run saves."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def save_best(
    args: argparse.Namespace,
    module: Any,
    name: str,
    out: Path,
    best_path: str,
    optim: Any,
    ended: dict[str, Any],
) -> tuple[Path, dict[str, Any]]:
    """Writes OUT/NAME.pt + NAME.json, each in one rename (written in a temporary folder in OUT first: an
    interrupted save leaves no half file); returns the weights' path and the training record they carry."""
    import shutil
    import tempfile

    from pipelines.commands.train_checkpoint import check_saved_predicts
    from predictors.base import OBS_LEN
    from predictors.checkpoint import save_checkpoint
    from predictors.durable import replace_durably, sync_folder

    extra = {
        "training": {
            "epochs": args.epochs,
            "best_checkpoint": Path(best_path).name,
            "seed": args.seed,
            "batch_size": args.batch_size,
            "batching": args.batching,  # how the scenes were cut into batches (predictors.data.batching)
            "pred_len": module.pred_len,  # steps it learned to predict: a longer MPC horizon extrapolates
            # only when set: a checkpoint trained on every batch, every epoch, reads as before
            **ended,
            "optim": {**optim.__dict__, "loss": module.trained_loss},
        }
    }
    _remove_killed_staging(out, name)
    staging = Path(tempfile.mkdtemp(prefix=f".{name}.", suffix=".part", dir=out))
    try:
        written = save_checkpoint(
            module.net, model=args.model, name=name, out_dir=staging, obs_len=OBS_LEN, extra=extra
        )
        check_saved_predicts(args.model, written[0], out)
        for path in written:  # out synced once, after both renames
            replace_durably(path, out / path.name, sync_target_folder=False)
        sync_folder(out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out / written[0].name, extra


def _remove_killed_staging(out: Path, name: str) -> None:
    """Remove the staging folders (.NAME.XXXXXXXX.part) of saves in ``out`` that a kill stopped (kill -9, or
    SIGTERM, which runs no finally): each held a copy of the weights, and stayed through every later run. No
    other save can be running into ``out``: the caller holds its lock (``one_run_at_a_time``)."""
    import re
    import shutil

    staging = re.compile(rf"\.{re.escape(name)}\.[a-z0-9_]{{8}}\.part")
    for entry in out.iterdir():
        if staging.fullmatch(entry.name) and entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
