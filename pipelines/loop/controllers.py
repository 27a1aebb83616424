"""The junction between the simulator and the robot controllers.

``crowdsim`` never imports ``mpc``; this module names what a controller is to the closed loop, and holds the
explicit registry of controllers (baselines from ``crowdsim.baselines``, the game-theoretic MPCs from
``pipelines.loop.mpc``). Factories import lazily so that choosing ``orca`` never loads CasADi solvers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from crowdsim.control import ControlOutput
from pipelines.errors import PipelineError
from pipelines.loop.margins import MarginSpec

if TYPE_CHECKING:
    from crowdsim.env import EnvConfig, Observation

__all__ = [
    "CONTROLLERS",
    "ControlOutput",
    "Controller",
    "ControllerSpec",
    "EpisodeObserver",
    "make_controller",
]

COUPLINGS = ("ibr", "nlp")


@dataclass(frozen=True)
class ControllerSpec:
    """What the user chose on the command line; the controller is built from it once per run."""

    controller: str  # a key of CONTROLLERS
    predictor: str = "constant_velocity"  # a name accepted by predictors.registry.load_predictor
    flocking: bool = True  # False: omega_floc = 0 (Table III, "NF")
    coupling: str = "ibr"  # "ibr": Algorithm 1/2; "nlp": the predictor inside the joint NLP
    record_iterations: bool = False  # keep the humans' prediction of every IBR iteration in ControlOutput
    mpc_overrides: tuple[tuple[str, Any], ...] = ()  # (field, value) pairs applied to mpc.config.MPCConfig
    margins: MarginSpec = MarginSpec()  # allowance for prediction error in Eq. 11 (pipelines/loop/margins.py)

    def __post_init__(self):
        if self.controller not in CONTROLLERS:
            raise PipelineError(f"unknown controller {self.controller!r}; choose from {sorted(CONTROLLERS)}")
        if self.coupling not in COUPLINGS:
            raise PipelineError(f"unknown coupling {self.coupling!r}; choose from {list(COUPLINGS)}")
        if not isinstance(self.margins, MarginSpec):
            raise PipelineError(f"margins must be a MarginSpec, got {self.margins!r}")
        if any(name == "human_margins" for name, _ in self.mpc_overrides):
            raise PipelineError("set human margins through ControllerSpec.margins, not mpc_overrides")


class Controller(Protocol):
    name: str

    def reset(self, obs: Observation) -> None:
        """Start a new episode (problem sizes are known from ``obs``)."""
        ...

    def act(self, obs: Observation) -> ControlOutput: ...


class EpisodeObserver(Protocol):
    """Hooks the closed loop calls; the MCAP recorder is one."""

    def on_reset(self, obs: Observation, meta: dict[str, Any]) -> None: ...

    def on_step(self, obs: Observation, out: ControlOutput, next_obs: Observation) -> None: ...

    def on_end(self, result: Any) -> None: ...


def _straight(spec: ControllerSpec, env_config: EnvConfig | None) -> Controller:
    from crowdsim.baselines import StraightController

    return StraightController()


def _orca(spec: ControllerSpec, env_config: EnvConfig | None) -> Controller:
    from crowdsim.baselines import OrcaController

    return OrcaController()


# The ORCA-ground-truth oracle needs the humans' goals and the simulator, so it is not in the predictor
# registry; its MPC controllers come from pipelines.oracle.
ORACLE_PREDICTOR = "orca_oracle"


def _mpc(spec: ControllerSpec, distributed: bool, env_config: EnvConfig | None) -> Controller:
    if spec.predictor == ORACLE_PREDICTOR:
        from pipelines.loop.oracle import make_oracle_controller

        return make_oracle_controller(spec, env_config)
    from pipelines.loop.mpc import make_mpc_controller

    return make_mpc_controller(spec, distributed=distributed)


def _cmpc(spec: ControllerSpec, env_config: EnvConfig | None) -> Controller:
    return _mpc(spec, False, env_config)


def _dmpc(spec: ControllerSpec, env_config: EnvConfig | None) -> Controller:
    return _mpc(spec, True, env_config)


CONTROLLERS: dict[str, Callable[[ControllerSpec, EnvConfig | None], Controller]] = {
    "straight": _straight,
    "orca": _orca,
    "cmpc": _cmpc,
    "dmpc": _dmpc,
}


def make_controller(spec: ControllerSpec, env_config: EnvConfig | None = None) -> Controller:
    """The controller of ``spec`` for episodes simulated under ``env_config`` (the ORCA oracle simulates the
    humans with it; None: the default conventions)."""
    return CONTROLLERS[spec.controller](spec, env_config)
