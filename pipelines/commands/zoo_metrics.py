"""What ``crowdmpc zoo add`` checks of a run's NAME.metrics.json before its figures go into the zoo beside the
weights: that they were measured on these weights and this config, and that a protocol label it is given does
not contradict the data the run recorded."""

from __future__ import annotations

from pathlib import Path

from pipelines.errors import PipelineError

# The protocols whose files TrajNet++'s ETH split fixes: a run recorded under one of them cannot be labelled
# another, nor can a run on other files take their name (its figures would sit among theirs in `zoo list`).
TRAJNET_PROTOCOLS = ("paper", "loo")


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


def check_metrics_describe(weights: Path, metrics_path: Path, summary: dict) -> None:
    """Refuse a metrics file that `crowdmpc train` wrote for other weights: the zoo entry would list metrics
    of other weights. Train records the weights' sha256 (since this check), and the checkpoint's name, model
    kind and epochs, which its config holds too (the config's errors are left to the loading that follows).
    The epochs tell apart a resumed run's new weights from the metrics of its earlier, shorter run."""
    from predictors import checkpoint
    from predictors.errors import PredictorError
    from predictors.hashing import sha256_file

    for key in ("name", "model", "weights_sha256"):
        if key in summary and not isinstance(summary[key], str):
            raise PipelineError(f'{metrics_path}: "{key}" must be a string (the checkpoint\'s {key})')
    recorded = summary.get("weights_sha256")
    if recorded is not None and weights.is_file() and recorded != sha256_file(weights):
        if not _reads_as_weights(weights):  # a truncated file was told to finish its run with --resume
            raise PipelineError(
                f"{weights} is not the file `crowdmpc train` wrote ({metrics_path} records sha256 "
                f"{recorded[:12]}…) and does not read as weights (truncated, or not a torch file): add the "
                "file train wrote, or train again"
            )
        raise PipelineError(
            f"{metrics_path} holds the metrics of weights with sha256 {recorded[:12]}…, not of {weights} "
            f"({sha256_file(weights)[:12]}…); pass the NAME.metrics.json `crowdmpc train` wrote beside these "
            "weights (a run stopped before writing it: finish it with `crowdmpc train --resume`)"
        )
    config = weights.with_suffix(".json")
    recorded_config = summary.get("config_sha256")
    if isinstance(recorded_config, str) and config.is_file() and recorded_config != sha256_file(config):
        raise PipelineError(
            f"{config} is not the config {metrics_path} was measured with (sha256 {recorded_config[:12]}…, "
            f"now {sha256_file(config)[:12]}…): an edited config with these weights is another model; add "
            "the files `crowdmpc train` wrote, unedited (or train again with the settings you want)"
        )
    if not ({"name", "model", "training"} & summary.keys()) or not config.is_file():
        return
    try:
        document = checkpoint.read_document(config, checkpoint.CONFIG_FORMAT, "crowdmpc predictor config")
    except PredictorError:
        return  # add_to_zoo refuses it with the whole story
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
