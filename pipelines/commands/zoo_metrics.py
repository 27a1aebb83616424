"""What ``crowdmpc zoo add`` checks of a run's NAME.metrics.json before its figures go into the zoo beside the
weights: that they were measured on these weights and this config, and that a protocol label it is given does
not contradict the data the run recorded."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import TYPE_CHECKING

from pipelines.commands.train_data import PROTOCOLS
from pipelines.errors import PipelineError

if TYPE_CHECKING:
    from predictors.checkpoint import CheckedPair

# The protocols whose files TrajNet++'s ETH split fixes: a run recorded under one of them cannot be labelled
# another, nor can a run on other files take their name (its figures would sit among theirs in `zoo list`).
TRAJNET_PROTOCOLS = PROTOCOLS
CONFIG_WHAT = "crowdmpc predictor config"


def check_protocol_label(label: str | None, summary: dict, metrics_path: Path) -> None:
    """Refuse ``zoo add --protocol LABEL`` that contradicts the protocol the run recorded: a model trained on
    one's own files was accepted as "paper", its test ADE of those files then listed among the ETH ones."""
    recorded = summary.get("protocol")
    if label is None or label == recorded or not isinstance(recorded, str):
        return
    if recorded in TRAJNET_PROTOCOLS or label in TRAJNET_PROTOCOLS:
        raise PipelineError(
            f"--protocol {label}: {metrics_path} records a run of protocol {recorded!r}; a label may name a "
            f"run of one's own files (custom) otherwise, never call one run another's "
            f"({', '.join(TRAJNET_PROTOCOLS)} name TrajNet++'s ETH files)"
        )


def _reads_as_weights(weights: Path) -> bool:
    """Whether ``weights`` loads as a torch file of tensors (``weights_only``, as every load here)."""
    from predictors.checkpoint import load_tensors

    try:
        load_tensors(weights)
    except Exception:  # whatever a damaged file makes torch raise
        return False
    return True


def check_metrics_describe(weights: Path, metrics_path: Path, summary: dict, checked: CheckedPair) -> None:
    """Refuse a metrics file that `crowdmpc train` wrote for other weights: the zoo entry would list metrics
    of other weights. Train records the weights' sha256 (since this check), and the checkpoint's name, model
    kind and epochs, which its config holds too. ``checked``: the pair as it loaded, whose bytes the zoo
    keeps (zoo_edit.add_entry's check_pair): hashed and parsed apart before the load, a pair replaced between
    the reads had its metrics checked against other bytes than were added.
    The epochs tell apart a resumed run's new weights from the metrics of its earlier, shorter run."""
    from predictors import checkpoint

    check_metrics_types(summary, metrics_path)
    recorded = summary.get("weights_sha256")
    found = hashlib.sha256(checked.weights).hexdigest()
    if recorded is not None and recorded != found:
        raise PipelineError(
            f"{metrics_path} holds the metrics of weights with sha256 {recorded[:12]}…, not of {weights} "
            f"({found[:12]}…); pass the NAME.metrics.json `crowdmpc train` wrote beside these "
            "weights (a run stopped before writing it: finish it with `crowdmpc train --resume`)"
        )
    config = weights.with_suffix(".json")
    recorded_config, found = summary.get("config_sha256"), hashlib.sha256(checked.config).hexdigest()
    if isinstance(recorded_config, str) and recorded_config != found:
        raise PipelineError(
            f"{config} is not the config {metrics_path} was measured with (sha256 {recorded_config[:12]}…, "
            f"now {found[:12]}…): an edited config with these weights is another model; add "
            "the files `crowdmpc train` wrote, unedited (or train again with the settings you want)"
        )
    document = checkpoint.parse_document(config, checked.config, checkpoint.CONFIG_FORMAT, CONFIG_WHAT)
    trained = document.get("training")
    own = {
        "name": document.get("name", weights.stem),
        "model": document.get("model"),
        "epochs": trained.get("epochs") if isinstance(trained, dict) else None,
    }
    claimed = {**summary, "epochs": summary.get("training", {}).get("epochs")}
    for key, value in own.items():
        if claimed.get(key) is not None and value is not None and claimed[key] != value:
            raise PipelineError(
                f"{metrics_path} holds the metrics of {key} {claimed[key]!r}, not of {weights} ({key} "
                f"{value!r} in {config.name}); pass the NAME.metrics.json "
                "`crowdmpc train` wrote beside these weights"
            )


def check_metrics_types(summary: dict, metrics_path: Path) -> None:
    """Refuse a metrics file whose record of the checkpoint is not strings, before the pair is read."""
    for key in ("name", "model", "weights_sha256"):
        if key in summary and not isinstance(summary[key], str):
            raise PipelineError(f'{metrics_path}: "{key}" must be a string (the checkpoint\'s {key})')


def unloadable_weights(weights: Path, metrics_path: Path, summary: dict) -> PipelineError | None:
    """The refusal of weights that did not load when they are not the file the metrics were measured on and
    do not read as weights (a truncated file was told to finish its run with --resume); None otherwise. The
    file is read again only to say so: nothing of it is added."""
    from predictors.hashing import sha256_file

    recorded = summary.get("weights_sha256")
    if not isinstance(recorded, str) or not weights.is_file() or recorded == sha256_file(weights):
        return None
    if _reads_as_weights(weights):
        return None
    return PipelineError(
        f"{weights} is not the file `crowdmpc train` wrote ({metrics_path} records sha256 "
        f"{recorded[:12]}…) and does not read as weights (truncated, or not a torch file): add the "
        "file train wrote, or train again"
    )
