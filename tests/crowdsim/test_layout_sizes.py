"""CrowdEnv.reset_layout's sizes and numbers: the limits of ``reset`` (MAX_ROBOTS, MAX_HUMANS), an empty list
as no agents, and no complex coordinates."""

import warnings

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from crowdsim.errors import SimulationError
from crowdsim.scenarios import MAX_HUMANS, MAX_ROBOTS, Layout, checked_layout


def spread(n: int, y: float) -> np.ndarray:
    """``n`` points 1 m apart on the line ``y``: no two agents in contact."""
    return np.stack([np.arange(n, dtype=float), np.full(n, y)], axis=1)


def test_more_robots_than_max_robots_are_refused_naming_the_limit():
    n = MAX_ROBOTS + 1
    layout = Layout(spread(n, -5.0), spread(n, 5.0), np.zeros((0, 2)), np.zeros((0, 2)))
    with pytest.raises(
        SimulationError, match=rf"robot_starts has {n} rows: at most MAX_ROBOTS = {MAX_ROBOTS}"
    ):
        CrowdEnv().reset_layout(layout)


def test_more_humans_than_max_humans_are_refused_naming_the_limit():
    n = MAX_HUMANS + 1
    layout = Layout(spread(1, -5.0), spread(1, 5.0), spread(n, 0.0), spread(n, 0.0))
    with pytest.raises(
        SimulationError, match=rf"human_starts has {n} rows: at most MAX_HUMANS = {MAX_HUMANS}"
    ):
        CrowdEnv().reset_layout(layout)


def test_the_limits_themselves_run():
    layout = Layout(
        spread(MAX_ROBOTS, -5.0), spread(MAX_ROBOTS, 5.0), spread(MAX_HUMANS, 0.0), spread(MAX_HUMANS, 1.0)
    )
    obs = CrowdEnv().reset_layout(layout)
    assert obs.robot_positions.shape == (MAX_ROBOTS, 2) and obs.human_positions.shape == (MAX_HUMANS, 2)


@pytest.mark.parametrize("empty", [[], np.array([]), np.zeros((0, 2))], ids=["list", "array", "0x2"])
def test_no_humans_as_an_empty_list_is_a_0_by_2_array(empty):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        obs = CrowdEnv().reset_layout(Layout([[0, 0]], [[0, 5]], empty, empty))  # type: ignore[arg-type]
    assert obs.human_positions.shape == (0, 2) and obs.robot_positions.tolist() == [[0.0, 0.0]]


def test_no_robots_as_an_empty_list_is_allowed():
    layout = checked_layout(Layout([], [], [[3, 0]], [[3, 0]]))  # type: ignore[arg-type]
    assert layout.robot_starts.shape == layout.robot_goals.shape == (0, 2)


def test_a_single_point_is_still_not_a_row():
    with pytest.raises(SimulationError, match=r"human_starts must be a \(N, 2\) array, got shape \(2,\)"):
        checked_layout(Layout([[0, 0]], [[0, 5]], [3, 0], [[3, 0]]))  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "value",
    [
        np.array([[3 + 1j, 0]]),
        np.array([[3 + 0j, 0]]),
        [[3 + 1j, 0.0]],
        np.array([[np.complex64(3), 0]], object),
    ],
    ids=["complex-array", "zero-imaginary", "python-complex", "object"],
)
def test_complex_coordinates_are_refused_not_truncated(value):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # before, numpy's ComplexWarning and the real part
        with pytest.raises(SimulationError, match="layout.human_starts must hold real numbers"):
            CrowdEnv().reset_layout(Layout([[0, 0]], [[0, 5]], value, [[3, 0]]))  # type: ignore[arg-type]
