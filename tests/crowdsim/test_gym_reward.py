"""crowdsim/gym_reward.py on its own: the reward's boundaries and validation, and the distances it is given,
by hand (tests/crowdsim/test_gym_env.py checks them through the environment)."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from crowdsim.errors import SimulationError
from crowdsim.gym_reward import RewardConfig, step_closest, surface_distances


def test_touching_boundaries_are_not_a_contact():
    # CrowdNav's collision is a boundary distance strictly below 0; at exactly 0 the step costs the
    # discomfort penalty (0 - 0.4) * 0.5 * 0.4 = -0.08, not the collision penalty -0.25.
    rule = RewardConfig().step_reward
    assert rule(0.0, success=False, dt=0.4) == pytest.approx(-0.08)
    assert rule(0.0, success=True, dt=0.4) == 1.0


def test_surface_distances_by_hand_and_without_humans():
    # Robot 0: closest human 1.0 m centre to centre -> 1.0 - 2 x 0.3 = 0.4 m; robot 1: 0.5 m -> -0.1 m.
    closest = np.array([[1.0, 2.0], [3.0, 0.5]])
    np.testing.assert_allclose(surface_distances(closest, 0.3), [0.4, -0.1])
    # No human: nobody near, inf (0 would read as touching and cost the discomfort penalty).
    assert surface_distances(np.zeros((2, 0)), 0.3).tolist() == [math.inf, math.inf]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"discomfort_dist": -0.1}, "discomfort_dist and discomfort_factor must be >= 0"),
        ({"discomfort_factor": -0.5}, "discomfort_dist and discomfort_factor must be >= 0"),
        ({"success": True}, "RewardConfig.success must be a finite number, got True"),  # a bool is no number
        ({"collision": math.inf}, "RewardConfig.collision must be a finite number, got inf"),
    ],
)
def test_bad_reward_numbers(kwargs, message):
    with pytest.raises(SimulationError, match=message):
        RewardConfig(**kwargs)


def test_step_closest_moves_the_robot_and_the_human_within_the_step():
    # The robot drives (0, 0) -> (1, 0) past a human standing at (1, 0.5): relative to the robot the human
    # goes (1, 0.5) -> (0, 0.5), closest 0.5 m at the step's end. A robot taken as standing at its start
    # would leave the human at (1, 0.5) throughout: sqrt(1.25) = 1.118 m.
    before = SimpleNamespace(
        human_present=None, robot_positions=np.array([[0.0, 0.0]]), human_positions=np.array([[1.0, 0.5]])
    )
    after = SimpleNamespace(
        human_present=None, robot_positions=np.array([[1.0, 0.0]]), human_positions=np.array([[1.0, 0.5]])
    )
    np.testing.assert_allclose(step_closest(before, after), [[0.5]])
    # A human walking (2, 1) -> (-2, 1) past a robot standing at the origin: sqrt(5) m at both ends of the
    # step, 1 m mid-step at (0, 1).
    before = SimpleNamespace(
        human_present=None, robot_positions=np.zeros((1, 2)), human_positions=np.array([[2.0, 1.0]])
    )
    after = SimpleNamespace(
        human_present=None, robot_positions=np.zeros((1, 2)), human_positions=np.array([[-2.0, 1.0]])
    )
    np.testing.assert_allclose(step_closest(before, after), [[1.0]])
