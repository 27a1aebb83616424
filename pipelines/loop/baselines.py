"""The simulator's baselines (``crowdsim.baselines``: straight line, ORCA) as closed-loop controllers.

``crowdsim`` knows nothing of predictors or episode metadata, so the facts the ``Controller`` protocol asks
for are stated here: no predictor, nothing to describe beyond the environment, nothing to release.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from crowdsim.control import ControlOutput
    from crowdsim.env import Observation


class SimulatorBaseline(Protocol):
    name: str

    def reset(self, obs: Observation) -> None: ...

    def act(self, obs: Observation) -> ControlOutput: ...


class BaselineController:
    """A ``Controller`` around a crowdsim baseline."""

    predictor: str | None = None

    def __init__(self, inner: SimulatorBaseline):
        self.inner = inner
        self.name = inner.name

    def reset(self, obs: Observation) -> None:
        self.inner.reset(obs)

    def act(self, obs: Observation) -> ControlOutput:
        return self.inner.act(obs)

    def describe(self) -> dict[str, Any]:
        return {"predictor_sha256": None, "config": {}}

    def close(self) -> None:
        pass
