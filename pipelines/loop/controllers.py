"""The junction between the simulator and the robot controllers: what a controller is to the closed loop.

``crowdsim`` never imports ``mpc``; this module names the controller protocol and holds the explicit, typed
registry of controllers: the baselines (``pipelines.loop.baselines`` adapts ``crowdsim.baselines``) and the
game-theoretic MPCs (``pipelines.loop.mpc``). What the pipelines must know before a controller exists (does
it plan with a predictor, can its NLPs be compiled) is stated per name in ``pipelines.loop.spec``; each
controller states the rest itself (``predictor``, ``describe``, ``close``). Builders import lazily so that
choosing ``orca`` never loads CasADi solvers.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Final, Protocol

from crowdsim.control import ControlOutput
from pipelines.loop.spec import (
    CONTROLLER_KINDS,
    COUPLINGS,
    ControllerKind,
    ControllerName,
    ControllerSpec,
    Coupling,
)

if TYPE_CHECKING:
    from crowdsim.env import EnvConfig, Observation

# The spec and the controllers' facts live in pipelines.loop.spec (the MPC adapter needs them, and the
# registry needs the adapter); they are re-exported here, the registry's public face.
__all__ = [
    "CONTROLLERS",
    "CONTROLLER_KINDS",
    "COUPLINGS",
    "ControlOutput",
    "Controller",
    "ControllerKind",
    "ControllerName",
    "ControllerSpec",
    "Coupling",
    "make_controller",
]


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


# (spec, env_config, jit) -> controller
Builder = Callable[[ControllerSpec, "EnvConfig | None", bool], Controller]


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


CONTROLLERS: Final[Mapping[ControllerName, Builder]] = {
    "straight": _straight,
    "orca": _orca,
    "cmpc": _cmpc,
    "dmpc": _dmpc,
}


def make_controller(
    spec: ControllerSpec, env_config: EnvConfig | None = None, *, jit: bool = False
) -> Controller:
    """The controller of ``spec`` for episodes simulated under ``env_config`` (a predictor that observes the
    simulator, the ORCA oracle, simulates the humans with it; None: the default conventions). ``jit``
    compiles the NLPs of a controller whose kind ``compiles`` and is ignored by the others."""
    return CONTROLLERS[spec.controller](spec, env_config, jit)
