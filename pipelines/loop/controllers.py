"""The junction between the simulator and the robot controllers: what a controller is to the closed loop.

``crowdsim`` never imports ``mpc``; this module names the controller protocol and holds the explicit, typed
registry of controllers: the baselines (``pipelines.loop.baselines`` adapts ``crowdsim.baselines``) and the
game-theoretic MPCs (``pipelines.loop.mpc``). Each registry entry states the facts the pipelines need before
a controller exists (does it plan with a predictor, can its NLPs be compiled); each controller states the
rest itself (``predictor``, ``describe``, ``close``). Builders import lazily so that choosing ``orca`` never
loads CasADi solvers.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final, Literal, Protocol, get_args

from crowdsim.control import ControlOutput
from pipelines.errors import PipelineError
from pipelines.loop.margins import MarginSpec

if TYPE_CHECKING:
    from crowdsim.env import EnvConfig, Observation
    from pipelines.loop.episode import EpisodeResult

__all__ = [
    "CONTROLLERS",
    "COUPLINGS",
    "ControlOutput",
    "Controller",
    "ControllerKind",
    "ControllerName",
    "ControllerSpec",
    "Coupling",
    "EpisodeObserver",
    "make_controller",
]

# Literal rather than Enum: the values travel unchanged through argparse, JSON records and MCAP metadata.
ControllerName = Literal["straight", "orca", "cmpc", "dmpc"]
Coupling = Literal["ibr", "nlp"]  # "ibr": Algorithm 1/2; "nlp": the predictor inside the joint NLP
COUPLINGS: Final[tuple[Coupling, ...]] = get_args(Coupling)


class Controller(Protocol):
    """A robot controller in the closed loop; it owns its failures (a step that cannot be solved falls back
    inside the controller and says so in ``ControlOutput.fallback``)."""

    name: str
    predictor: str | None  # the pedestrian predictor it plans with, None for a controller that uses none

    def reset(self, obs: Observation) -> None:
        """Start a new episode (problem sizes are known from ``obs``)."""
        ...

    def act(self, obs: Observation) -> ControlOutput: ...

    def describe(self) -> dict[str, Any]:
        """What the episode metadata records about this controller: ``predictor_sha256`` and ``config``."""
        ...

    def close(self) -> None:
        """Release what it holds (solver threads); it may still be used after."""
        ...


class EpisodeObserver(Protocol):
    """Hooks the closed loop calls; the MCAP recorder is one."""

    def on_reset(self, obs: Observation, meta: Mapping[str, Any]) -> None: ...

    def on_step(self, obs: Observation, out: ControlOutput, next_obs: Observation) -> None: ...

    def on_end(self, result: EpisodeResult) -> None: ...


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
        if self.controller not in CONTROLLERS:
            raise PipelineError(f"unknown controller {self.controller!r}; choose from {sorted(CONTROLLERS)}")
        if self.coupling not in COUPLINGS:
            raise PipelineError(f"unknown coupling {self.coupling!r}; choose from {list(COUPLINGS)}")
        if not isinstance(self.margins, MarginSpec):
            raise PipelineError(f"margins must be a MarginSpec, got {self.margins!r}")
        if any(name == "human_margins" for name, _ in self.mpc_overrides):
            raise PipelineError("set human margins through ControllerSpec.margins, not mpc_overrides")

    @property
    def kind(self) -> ControllerKind:
        return CONTROLLERS[self.controller]

    @property
    def predictor_name(self) -> str | None:
        """The predictor this spec's controller plans with; None for a controller that uses none."""
        return self.predictor if self.kind.uses_predictor else None


Builder = Callable[[ControllerSpec, "EnvConfig | None", bool], Controller]


@dataclass(frozen=True)
class ControllerKind:
    """A registry entry: how to build the controller, and what the pipelines must know before it exists."""

    build: Builder  # (spec, env_config, jit) -> controller
    uses_predictor: bool  # plans with spec.predictor (records and cell keys name it)
    compiles: bool  # jit=True compiles its NLPs to C (MPCConfig.jit); it changes speed, not results


def _straight(spec: ControllerSpec, env_config: EnvConfig | None, jit: bool) -> Controller:
    from crowdsim.baselines import StraightController
    from pipelines.loop.baselines import BaselineController

    return BaselineController(StraightController())


def _orca(spec: ControllerSpec, env_config: EnvConfig | None, jit: bool) -> Controller:
    from crowdsim.baselines import OrcaController
    from pipelines.loop.baselines import BaselineController

    return BaselineController(OrcaController())


def _cmpc(spec: ControllerSpec, env_config: EnvConfig | None, jit: bool) -> Controller:
    from pipelines.loop.mpc import MPCController

    return MPCController(spec, distributed=False, env_config=env_config, jit=jit)


def _dmpc(spec: ControllerSpec, env_config: EnvConfig | None, jit: bool) -> Controller:
    from pipelines.loop.mpc import MPCController

    return MPCController(spec, distributed=True, env_config=env_config, jit=jit)


CONTROLLERS: Final[Mapping[ControllerName, ControllerKind]] = {
    "straight": ControllerKind(_straight, uses_predictor=False, compiles=False),
    "orca": ControllerKind(_orca, uses_predictor=False, compiles=False),
    "cmpc": ControllerKind(_cmpc, uses_predictor=True, compiles=True),
    "dmpc": ControllerKind(_dmpc, uses_predictor=True, compiles=True),
}
assert set(CONTROLLERS) == set(get_args(ControllerName))


def make_controller(
    spec: ControllerSpec, env_config: EnvConfig | None = None, *, jit: bool = False
) -> Controller:
    """The controller of ``spec`` for episodes simulated under ``env_config`` (a predictor that observes the
    simulator, the ORCA oracle, simulates the humans with it; None: the default conventions). ``jit``
    compiles the NLPs of a controller whose kind ``compiles`` and is ignored by the others."""
    return spec.kind.build(spec, env_config, jit)
