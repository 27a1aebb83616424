"""The junction between the simulator and the robot controllers.

``crowdsim`` never imports ``mpc``; this module names what a controller is to the closed loop, and holds the
explicit registry of controllers (baselines from ``crowdsim.baselines``, the game-theoretic MPCs from
``pipelines.mpc_controllers``). Factories import lazily so that choosing ``orca`` never loads CasADi solvers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from pipelines.errors import PipelineError

if TYPE_CHECKING:
    from crowdsim.env import Observation

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

    def __post_init__(self):
        if self.controller not in CONTROLLERS:
            raise PipelineError(f"unknown controller {self.controller!r}; choose from {sorted(CONTROLLERS)}")
        if self.coupling not in COUPLINGS:
            raise PipelineError(f"unknown coupling {self.coupling!r}; choose from {list(COUPLINGS)}")


@dataclass(frozen=True)
class ControlOutput:
    """One control step's decision and what it cost to make it."""

    accelerations: np.ndarray  # (M, 2) m/s^2, the actions to apply now
    solve_time_s: float = 0.0  # wall time of the whole control step (prediction + all solves)
    status: str = "ok"  # solver status of the step ("ok" for the baselines)
    iterations: int = 0  # IBR iterations used (0 for the baselines)
    fallback: str | None = None  # None, "shifted" (previous plan shifted) or "brake"
    potential: float | None = None  # F_t, Eq. (16), at the returned plan
    plan: np.ndarray | None = None  # (M, H, 2) planned robot positions at t+1..t+H
    prediction: np.ndarray | None = None  # (H, N_h, 2) predicted human positions used by the final solve
    iteration_predictions: tuple[np.ndarray, ...] = ()  # (H, N_h, 2) per IBR iteration, when asked
    extra: dict[str, Any] = field(default_factory=dict)  # controller-specific numbers (JSON-serialisable)


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


def _straight(spec: ControllerSpec) -> Controller:
    from crowdsim.baselines import StraightController

    return StraightController()


def _orca(spec: ControllerSpec) -> Controller:
    from crowdsim.baselines import OrcaController

    return OrcaController()


def _cmpc(spec: ControllerSpec) -> Controller:
    from pipelines.mpc_controllers import make_mpc_controller

    return make_mpc_controller(spec, distributed=False)


def _dmpc(spec: ControllerSpec) -> Controller:
    from pipelines.mpc_controllers import make_mpc_controller

    return make_mpc_controller(spec, distributed=True)


CONTROLLERS: dict[str, Callable[[ControllerSpec], Controller]] = {
    "straight": _straight,
    "orca": _orca,
    "cmpc": _cmpc,
    "dmpc": _dmpc,
}


def make_controller(spec: ControllerSpec) -> Controller:
    return CONTROLLERS[spec.controller](spec)
