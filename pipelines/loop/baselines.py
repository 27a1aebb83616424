"""The simulator's baselines (``crowdsim.baselines``: straight line, ORCA) as closed-loop controllers.

``crowdsim`` knows nothing of predictors or episode metadata, so the facts the ``Controller`` protocol asks
for are stated here: no predictor, nothing to describe beyond the environment, nothing to release.
``straight`` and ``orca`` build them for the simulator they will drive, as the MPC is built for it: the
robot bounds from ``EnvConfig.world()``, and the ORCA robots with the humans' ORCA parameters and radius
margin.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

from pipelines.loop.observed import check_state

if TYPE_CHECKING:
    from crowdsim.control import ControlOutput
    from crowdsim.env import Observation
    from crowdsim.env_config import EnvConfig


class SimulatorBaseline(Protocol):
    name: str

    def reset(self, obs: Observation) -> None: ...

    def act(self, obs: Observation) -> ControlOutput: ...


class BaselineController:
    """A ``Controller`` around a crowdsim baseline."""

    predictor: str | None = None

    def __init__(self, inner: SimulatorBaseline, env_config: EnvConfig | None = None):
        self.inner = inner
        self.name = inner.name
        self.env_config = env_config  # the simulator it was built for (the loops refuse another world)

    def reset(self, obs: Observation) -> None:
        check_state(obs)
        self.inner.reset(obs)

    def act(self, obs: Observation) -> ControlOutput:
        check_state(obs)
        return self.inner.act(obs)

    def describe(self) -> dict[str, Any]:
        return {"predictor_sha256": None, "config": {}}

    def close(self) -> None:
        pass


def straight(env_config: EnvConfig | None = None) -> BaselineController:
    """The straight-line robots within ``env_config``'s robot bounds (None: the defaults)."""
    from crowdsim.baselines import StraightController

    env = _env(env_config)
    world = env.world()
    return BaselineController(StraightController(v_max=world.v_max, a_max=world.a_max), env)


def orca(env_config: EnvConfig | None = None) -> BaselineController:
    """The ORCA robots within ``env_config``'s robot bounds, with the ORCA parameters and radius margin its
    humans get (None: the defaults)."""
    from crowdsim.baselines import OrcaController

    env = _env(env_config)
    world = env.world()
    return BaselineController(
        OrcaController(
            v_max=world.v_max, a_max=world.a_max, params=env.orca, radius_margin=env.orca_radius_margin
        ),
        env,
    )


def _env(env_config: EnvConfig | None) -> EnvConfig:
    from crowdsim.env_config import EnvConfig

    return env_config if env_config is not None else EnvConfig()
