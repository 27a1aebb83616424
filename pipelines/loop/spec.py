"""What the user chooses: the controller spec, its option types, and each controller's standing facts.

The facts are what the pipelines need before a controller is built: whether it plans with a predictor (its
records and cell keys then name one) and whether its NLPs can be compiled. The builders that turn a spec
into a controller are the registry of ``pipelines.loop.controllers``, which checks it covers these names.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final, Literal, get_args

from pipelines.errors import PipelineError
from pipelines.loop.margins import MarginSpec

# Literal rather than Enum: the values travel unchanged through argparse, JSON records and MCAP metadata.
ControllerName = Literal["straight", "orca", "cmpc", "dmpc"]
Coupling = Literal["ibr", "nlp"]  # "ibr": Algorithm 1/2; "nlp": the predictor inside the joint NLP
COUPLINGS: Final[tuple[Coupling, ...]] = get_args(Coupling)


@dataclass(frozen=True)
class ControllerKind:
    """A controller's standing facts."""

    uses_predictor: bool  # plans with spec.predictor (records and cell keys name it)
    compiles: bool  # jit=True compiles its NLPs to C (MPCConfig.jit); it changes speed, not results


CONTROLLER_KINDS: Final[Mapping[ControllerName, ControllerKind]] = {
    "straight": ControllerKind(uses_predictor=False, compiles=False),
    "orca": ControllerKind(uses_predictor=False, compiles=False),
    "cmpc": ControllerKind(uses_predictor=True, compiles=True),
    "dmpc": ControllerKind(uses_predictor=True, compiles=True),
}


@dataclass(frozen=True)
class ControllerSpec:
    """What the user chose on the command line; the controller is built from it once per run."""

    controller: ControllerName
    predictor: str = "constant_velocity"  # a name accepted by predictors.registry.load_predictor
    flocking: bool = True  # False: omega_floc = 0 (Table III, "NF")
    coupling: Coupling = "ibr"
    record_iterations: bool = False  # keep the humans' prediction of every IBR iteration in ControlOutput
    mpc_overrides: tuple[tuple[str, Any], ...] = ()  # (field, value) pairs applied to mpc.config.MPCConfig
    margins: MarginSpec = MarginSpec()  # allowance for prediction error in Eq. 11 (pipelines/loop/margins.py)

    def __post_init__(self) -> None:
        if self.controller not in CONTROLLER_KINDS:
            raise PipelineError(
                f"unknown controller {self.controller!r}; choose from {sorted(CONTROLLER_KINDS)}"
            )
        if self.coupling not in COUPLINGS:
            raise PipelineError(f"unknown coupling {self.coupling!r}; choose from {list(COUPLINGS)}")
        if not isinstance(self.margins, MarginSpec):
            raise PipelineError(f"margins must be a MarginSpec, got {self.margins!r}")
        if any(name == "human_margins" for name, _ in self.mpc_overrides):
            raise PipelineError("set human margins through ControllerSpec.margins, not mpc_overrides")

    @property
    def kind(self) -> ControllerKind:
        return CONTROLLER_KINDS[self.controller]

    @property
    def predictor_name(self) -> str | None:
        """The predictor this spec's controller plans with; None for a controller that uses none."""
        return self.predictor if self.kind.uses_predictor else None
