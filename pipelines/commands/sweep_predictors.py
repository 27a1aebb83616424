"""What a sweep's plan reads of the zoos before any worker starts (``check_predictors``): the entry each
of its predictors loads and the model it loads, read once for the other checks and the notes, a refusal
kept for the notes first (``read_predictors``)."""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

from pipelines.errors import PipelineError

if TYPE_CHECKING:
    from collections.abc import Mapping

    from pipelines.experiments.cells import Experiment
    from pipelines.experiments.checked_calibrations import Checked, CheckedInputs
    from pipelines.loop.margins_read import Planned
    from predictors.base import Predictor
    from predictors.errors import PredictorError
    from predictors.manifest import ZooEntry


class PlanModels(NamedTuple):
    """What ``check_predictors`` read of the zoos, for the other checks and the notes."""

    loaded: dict[str, Predictor]  # the zoo models the plan's methods plan with, by name
    entries: dict[str, ZooEntry]  # the zoo entry each of them loads (a registered predictor has none)
    # the calibration block each method plans with, by label, or its refusal (``planned_margins``'), None:
    # not looked up yet
    blocks: dict[str, Planned] | None = None
    # ``read_predictors``: the refusal of predictors no zoo holds (``loaded`` then empty) or of a model that
    # does not load (the first, in name order: the others are not loaded; ``loaded`` then holds the models
    # before it), which ``check_predictors`` raises
    refused: PipelineError | PredictorError | None = None

    def weights(self) -> dict[str, str | None]:
        """The sha256 of the weights each model ``loaded`` holds, by name, which a sweep's workers must load
        (pipelines.experiments.checked_weights)."""
        from predictors.registry import loaded_sha256

        return {name: loaded_sha256(model) for name, model in self.loaded.items()}

    def calibrations(self) -> Checked | None:
        """The block each method plans with, by label, which a sweep's workers plan with and its resume
        checks the records against (pipelines.experiments.checked_calibrations); None: not looked up."""
        from pipelines.experiments.checked_calibrations import checked_blocks

        return None if self.blocks is None else checked_blocks(self.blocks)

    def checked(self) -> CheckedInputs:
        """``weights`` and ``calibrations`` (a method not there: looked up by whoever takes them), which a
        dry run checks the records of a resume and of --reuse against, as the run does."""
        from pipelines.experiments.checked_calibrations import CheckedInputs

        return CheckedInputs(self.weights(), self.calibrations() or {})


def check_predictors(experiment: Experiment, chosen_by: Mapping[str, str] | None = None) -> PlanModels:
    """Fail before starting workers, not once per episode in errors.jsonl: every predictor is registered or
    in a zoo, a zoo model's kind is registered (a plugin's, with --plugin, which the workers inherit; its
    config's, which builds it, not its manifest entry's, which `zoo verify` checks against it), and it
    loads as simulate loads it (its files' sha256 as its manifest records them, its net's contract), each
    refusal simulate's one line. ``chosen_by``: a predictor's name -> where the run chose it ("run.toml:
    controller.predictor", "--predictors"), which its refusal names first. Returns the zoo models loaded,
    by name, for the couplings' and margins' checks (``check_plan``), with their entries, for the notes
    (``method_notes``): each read again, a `zoo add --replace` between the reads had one check pass weights
    the next did not see."""
    models = read_predictors(experiment, chosen_by)
    if models.refused is not None:
        raise models.refused
    return models


def read_predictors(experiment: Experiment, chosen_by: Mapping[str, str] | None = None) -> PlanModels:
    """``check_predictors``' reads, a name no zoo holds, a model whose kind is not registered or that does
    not load kept as ``refused`` (the other refusals, of a damaged manifest, raised) with the entries of
    every zoo predictor the plan names, so that the notes printed before that refusal describe the entries
    located here: they located each again and looked each method's calibration block up once a note, so a
    corrupt social_lstm_eth.pt had Table II's `sweep --margins conformal:0.1 --dry-run` read manifest.json
    12 times and calibrations.json 10 times (an unknown name: twice, 22 times with those margins)."""
    from predictors import zoo
    from predictors.errors import PredictorError
    from predictors.registry import PREDICTORS

    chosen_by = chosen_by or {}
    # only the predictors some method plans with: an orca or straight column loads none, and registered ones
    # need no zoo (a damaged user manifest stopped a sweep of constant velocity and ORCA)
    wanted = {name for _, spec in experiment.methods if (name := spec.predictor_name) is not None}
    if wanted <= set(PREDICTORS):
        return PlanModels({}, {})
    # both manifests read once: the entry each name loads (shipped first)
    entries: dict[str, zoo.Located] = {}
    for located in zoo.zoo_entries():
        entries.setdefault(located.entry.name, located)
    known = set(PREDICTORS) | set(entries)
    missing = sorted(wanted - known)
    # the entries of the names some zoo holds: the notes printed before a refusal read these, where they
    # located each name again (the manifest read twice before `sweep --predictor nope` refused)
    found = {name: entries[name].entry for name in sorted(wanted & set(entries) - set(PREDICTORS))}
    if missing:
        where = next((chosen_by[name] for name in missing if name in chosen_by), None)
        option = "--predictors" if experiment.predictor_list else "--predictor"
        hint = f"check the names {option} gives, or " if where is None else ""
        refused = PipelineError(
            f"{'' if where is None else f'{where}: '}experiment {experiment.name!r} needs predictors "
            f"{missing} that are not available; available: {sorted(known)} ({hint}train or fetch the zoo "
            "models)"
        )
        return PlanModels({}, found, refused=refused)  # nothing loaded: the plan stops at its notes
    names = sorted(found)
    loaded: dict[str, Predictor] = {}
    for name in names:
        located = entries[name]
        where = f"{chosen_by[name]}: " if name in chosen_by else ""
        try:
            loaded[name] = zoo.load_located(located)  # what every worker would do first, and fail at
        except (PipelineError, PredictorError) as exc:
            # a kind no plugin registers: the load's own line, naming the entry (zoo.check_kind), as
            # simulate's; an entry's kind looked up here had a manifest edited to an unknown kind said
            # instead of why its files did not load
            return PlanModels(loaded, found, refused=PipelineError(f"{where}{exc}") if where else exc)
    return PlanModels(loaded, found)
