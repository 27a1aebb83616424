"""What ``crowdmpc simulate`` reads of the zoo, read once for its checks, its notes and its controller: the
predictor's entry (the manifest), its weights and config, and the calibration block its margins plan with.
Each read apart, a `zoo add --replace` or a calibrate run between the reads had the notes describe, or a
check pass, other files than the episodes planned with."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from pipelines.errors import PipelineError
from pipelines.loop.spec import MPC_CONTROLLERS, is_shipped
from predictors.errors import PredictorError

if TYPE_CHECKING:
    from types import EllipsisType

    from crowdsim.world import WorldFacts
    from pipelines.config import RunConfig
    from pipelines.loop.controllers import ControllerReads, ControllerSpec
    from pipelines.loop.margins_read import Planned
    from predictors.base import Predictor
    from predictors.manifest import ZooEntry
    from predictors.zoo import Located as ZooLocated


@dataclass(frozen=True)
class PredictorRead:
    """A run's predictor as read from the zoo."""

    located: ZooLocated | None  # the entry it loads; None: a registered predictor, or a name no zoo holds
    model: Predictor | None  # None: not loaded here (the controller loads it, or refuses it, itself)
    # the refusal of its load here (a corrupt checkpoint), which the controller raises where it loads it
    refused: PipelineError | PredictorError | None = None

    @property
    def entry(self) -> ZooEntry | None:
        return None if self.located is None else self.located.entry


def load_checked(name: str) -> tuple[ZooLocated | None, Predictor]:
    """``name``'s zoo entry (None: a registered predictor) and the predictor it loads, refused as
    ``load_predictor`` refuses it."""
    from predictors.registry import load_predictor
    from predictors.zoo import load_located, locate

    located = None if _registered(name) else locate(name)
    return located, load_predictor(name) if located is None else load_located(located)


def read_predictor(spec: ControllerSpec) -> PredictorRead:
    """The predictor ``spec`` plans with, its entry located (a manifest that does not read is refused here)
    and, for a shipped MPC, loaded; a model that does not load is kept as ``refused``, which the controller
    raises in its own words after simulate's notes, as before, loading nothing again."""
    from predictors.registry import load_predictor
    from predictors.zoo import load_located, locate

    name = spec.predictor_name
    if name is None:
        return PredictorRead(None, None)
    registered = _registered(name)
    located = None if registered else locate(name)
    if not (is_shipped(spec.controller) and spec.controller in MPC_CONTROLLERS):
        return PredictorRead(located, None)  # a plugin controller loads its own
    try:
        model = load_predictor(name) if registered else None if located is None else load_located(located)
    except (PipelineError, PredictorError) as exc:
        return PredictorRead(located, None, exc)
    return PredictorRead(located, model)


def planned_calibration(
    spec: ControllerSpec,
    model: Predictor | None,
    world: WorldFacts,
    entry: ZooEntry | None = None,
    refused: PipelineError | PredictorError | None = None,
) -> Planned | EllipsisType:
    """``spec.margins.located`` as the MPC of ``spec`` (behind the run's sensor) built in ``world`` reads it
    with ``model`` (of the zoo ``entry``, None: a registered predictor): the block its notes describe and it
    plans with, or its ``Refused``, which the controller raises after its own checks (the world's sampling
    time first: the cause, not a symptom), the notes describing the block it refused, as they did when
    each looked it up. ``refused``: the model's load refused, raised by the controller as it loads it, the
    notes describing the block stored for the ``entry``'s weights (``load_refused``). ``...`` where
    ``model`` was not loaded here or the MPC's settings refuse: the controller reads it."""
    from pipelines.loop.margins_read import load_refused, look_up
    from pipelines.loop.mpc_setup import mpc_config
    from predictors.registry import loaded_sha256

    if not (is_shipped(spec.controller) and spec.controller in MPC_CONTROLLERS):
        return ...
    kind = None if entry is None else entry.model
    if refused is not None and spec.predictor_name is not None:
        sha256 = None if entry is None else entry.sha256  # the notes' checkpoint_sha256 of the name
        return load_refused(spec.margins, spec.predictor_name, sha256, kind, refused)
    if model is None:
        return ...
    try:
        horizon = mpc_config(spec, world=world).horizon
    except (PipelineError, PredictorError):
        return ...
    return look_up(spec.margins, model.name, horizon, loaded_sha256(model), kind)


def read_once(
    read: PredictorRead | None, spec: ControllerSpec, config: RunConfig
) -> tuple[ZooEntry | None, ControllerReads]:
    """The zoo entry simulate's notes describe and what its controller plans with, read once: the predictor
    as ``read`` (the checks') holds it, else read here (a plugin loads the entry located here), and the
    block its margins plan with (a load that refused: its refusal, raised by the controller)."""
    from pipelines.loop.controllers import ControllerReads
    from pipelines.loop.margins_read import Refused

    read = read or read_predictor(spec)
    behind = spec.behind(config.simulate.sensor_range, config.simulate.sensor_tracks)
    calibration = planned_calibration(behind, read.model, config.env.world(), read.entry, read.refused)
    model = read.model if read.refused is None else Refused(read.refused)  # raised as the MPC loads it
    return read.entry, ControllerReads(model, calibration, read.located)


def _registered(name: str) -> bool:
    from predictors.registry import PREDICTORS

    return name in PREDICTORS
