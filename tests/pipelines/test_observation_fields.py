"""Fields of a hand-built observation (a real robot's loop, docs/extending.md section 7) that passed the
checks and went wrong later: a NaN goal of a human under the ORCA oracle (every step fell back to the
shifted plan, saying only its status), a NaN or zero ``radius`` (every robot off its goal for good)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
from predictors.errors import PredictorError


def _act(spec: ControllerSpec, **fields) -> None:
    obs = dataclasses.replace(CrowdEnv().reset(0, "circle", 3, 3), **fields)
    controller = make_controller(spec)
    try:
        controller.reset(obs)
        controller.act(obs)
    finally:
        controller.close()


@pytest.mark.parametrize("field", ["human_goals", "human_velocities"])
def test_the_oracle_refuses_a_human_it_cannot_move(field):
    obs = CrowdEnv().reset(0, "circle", 3, 3)
    values = np.array(getattr(obs, field), dtype=float)
    values[1, 0] = np.nan
    with pytest.raises(PredictorError, match=rf"^obs\.{field} of human 1 is not finite \(\[nan, "):
        _act(ControllerSpec("cmpc", "orca_oracle"), **{field: values})
    _act(ControllerSpec("cmpc"), **{field: values})  # a model reads neither: left as it was


@pytest.mark.parametrize("radius", [float("nan"), 0.0, -0.3, float("inf"), True, "0.3"])
@pytest.mark.parametrize("controller", ["cmpc", "orca"])
def test_a_radius_that_is_no_length_is_refused(radius, controller):
    with pytest.raises(
        PipelineError, match=r"^obs\.radius must be a number of metres > 0 \(a robot's arrival\)"
    ):
        _act(ControllerSpec(controller), radius=radius)
