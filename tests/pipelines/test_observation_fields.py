"""Fields of a hand-built observation (a real robot's loop, docs/extending.md section 7) that passed the
checks and went wrong later: a NaN goal of a human under the ORCA oracle (every step fell back to the
shifted plan, saying only its status), a NaN or zero ``radius`` (every robot off its goal for good)."""

from __future__ import annotations

import dataclasses
import re

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


@pytest.mark.parametrize("step", [-1, 2.5, float("nan"), True, "3", None])
@pytest.mark.parametrize("controller", ["cmpc", "orca"])
def test_a_step_that_is_no_count_of_periods_is_refused(step, controller):
    # with human_observed None every human counts as seen step + 1 times (the per-class margins read it)
    with pytest.raises(PipelineError, match=r"^obs\.step must be an int >= 0 \(control periods since"):
        _act(ControllerSpec(controller), step=step)


@pytest.mark.parametrize("time", [-0.4, float("nan"), float("inf"), True, "0.4", None])
def test_a_time_that_is_no_number_of_seconds_is_refused(time):
    with pytest.raises(PipelineError, match=r"^obs\.time must be a finite number of seconds >= 0"):
        _act(ControllerSpec("cmpc"), time=time)


def test_numpy_scalars_of_a_clock_are_taken():
    _act(ControllerSpec("orca"), step=np.int64(3), time=np.float32(1.2))


@pytest.mark.parametrize(
    ("value", "got"),
    [
        (None, "shape (): None"),
        ([[0.0, 1.0], [2.0]], "rows of different lengths"),
        (np.zeros(4), "shape (4,)"),
    ],
)
@pytest.mark.parametrize("field", ["human_positions", "robot_positions"])
def test_positions_that_are_no_rows_of_points_are_refused(field, value, got):
    # None for "no humans" failed in len() as a TypeError before any check
    with pytest.raises(
        PipelineError, match=rf"^obs\.{field} must be an \(n, 2\) array .* got {re.escape(got)}"
    ):
        _act(ControllerSpec("cmpc"), **{field: value})


def test_no_humans_is_an_empty_array():
    _act(
        ControllerSpec("orca"),
        human_positions=np.zeros((0, 2)),
        human_velocities=np.zeros((0, 2)),
        human_goals=np.zeros((0, 2)),
        history=CrowdEnv().reset(0, "circle", 3, 3).history[:, :3],
    )
