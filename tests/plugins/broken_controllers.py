"""A controller plugin that breaks the documented contract: ``act`` returns the bare accelerations (an
ndarray) instead of a ``ControlOutput``. Registered as ``tests.plugins.broken_controllers:ArrayAct``."""

from __future__ import annotations

import numpy as np

from crowdsim.env import Observation
from tests.plugins.toy_controller import StraightLine


class ArrayAct(StraightLine):
    name = "array_act"

    def act(self, obs: Observation) -> np.ndarray:  # type: ignore[override]
        return super().act(obs).accelerations
