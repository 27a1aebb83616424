"""``crowdmpc train --resume``: what a run was started with, and the checks that a resume continues that run
(``pipelines.commands.train`` calls them before Lightning starts). The weights, optimiser and schedule come
back from last.ckpt whatever the command line says, so a resume asking for other settings, or a last.ckpt of
another model, is refused in one line rather than trained on and recorded wrongly."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from pipelines.errors import PipelineError

# What fixes a training run: --resume continues it with these, and only --epochs may change.
SETTINGS_FILE = "train_settings.json"


def run_settings(args: argparse.Namespace, net_config: Any, name: str, files: dict[str, list[Path]]) -> dict:
    from predictors.models import model_kind

    return {
        "name": name,
        "model": args.model,
        "net_config": model_kind(args.model).config_dict(net_config),
        "lr": args.lr,
        "step_size": args.step_size,
        "loss": args.loss,
        "seed": args.seed,
        "batch_size": args.batch_size,
        "files": {split: [str(p.resolve()) for p in paths] for split, paths in files.items()},
    }


def check_resumed_settings(out: Path, settings: dict[str, Any], *, name_given: bool) -> str:
    """The run's name; PipelineError when the command asks for other settings than the run in ``out`` was
    started with: the weights, optimiser and schedule resume from last.ckpt whatever the command says, so the
    written NAME.json would record settings that never trained them. Runs from before the settings were kept
    have no file, and are not checked."""
    path = out / SETTINGS_FILE
    if not path.is_file():
        return str(settings["name"])
    try:
        recorded = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise PipelineError(f"--resume: {path} is not readable JSON ({exc})") from None
    if not name_given:  # the default name follows the options, which are checked below
        settings = {**settings, "name": recorded.get("name", settings["name"])}
    differ = [k for k in settings if k in recorded and recorded[k] != settings[k]]
    if differ:
        shown = "; ".join(f"{k}: run {_short(recorded[k])}, now {_short(settings[k])}" for k in differ)
        raise PipelineError(
            f"--resume: {out} was started with other settings ({shown}); resume with the run's settings "
            "(only --epochs may change) or start a new run with another --out"
        )
    return str(settings["name"])


def check_last_checkpoint(last: Path, settings: dict[str, Any]) -> None:
    """PipelineError unless ``last`` is a Lightning checkpoint (read as weights only, as Lightning reads it)
    of the model kind and net config asked for: a cut, foreign or other-model file otherwise fails inside
    Lightning with a traceback (the run's settings file, when there is one, was checked before)."""
    import torch

    try:
        checkpoint = torch.load(last, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises RuntimeError, UnpicklingError, EOFError ... for a bad file
        first = (str(exc).strip().splitlines() or [""])[0][:160]
        raise PipelineError(
            f"--resume: {last} is not a readable Lightning checkpoint ({type(exc).__name__}: {first})"
        ) from None
    hyper = checkpoint.get("hyper_parameters") if isinstance(checkpoint, dict) else None
    if not isinstance(hyper, dict) or "state_dict" not in checkpoint:
        raise PipelineError(f"--resume: {last} is not a crowdmpc training checkpoint (no hyper-parameters)")
    asked = {"model": settings["model"], "net_config": settings["net_config"]}
    held = {"model": hyper.get("model", "social_gan" if "discriminator_config" in hyper else None)}
    held["net_config"] = hyper.get("net_config")
    differ = [k for k in asked if held[k] is not None and held[k] != asked[k]]
    if differ:
        shown = "; ".join(f"{k}: checkpoint {_short(held[k])}, now {_short(asked[k])}" for k in differ)
        raise PipelineError(f"--resume: {last} was trained with another model ({shown})")


def _short(value: Any) -> str:
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= 80 else text[:77] + "..."
