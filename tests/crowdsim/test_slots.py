"""Goals as formation slots (crowdsim/slots.py): the matching by hand and against every permutation, and
the simulator's use of it."""

import itertools

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from crowdsim.errors import LayoutWarning, SimulationError
from crowdsim.scenarios import Layout
from crowdsim.slots import SLOT_HYSTERESIS, match_slots


def test_two_robots_swap_by_hand():
    # Robot 0 stands 0.1 m from goal 1 and robot 1 0.1 m from goal 0: held as given, 2 * 1.9^2 = 7.22 m^2;
    # swapped, 2 * 0.1^2 = 0.02 m^2.
    goals = np.array([[0.0, 0.0], [2.0, 0.0]])
    positions = np.array([[1.9, 0.0], [0.1, 0.0]])
    np.testing.assert_array_equal(match_slots(positions, goals), [1, 0])
    np.testing.assert_array_equal(match_slots(positions[::-1], goals), [0, 1])


def test_near_tie_keeps_the_goals():
    # Each robot 0.01 m past the bisector of the two goals, towards the other's goal: swapping gains
    # 2 * (1.01^2 - 0.99^2) = 0.08 m^2, which a hysteresis of 0.1 m^2 refuses and one of 0.05 m^2 takes.
    goals = np.array([[-1.0, 0.0], [1.0, 0.0]])
    positions = np.array([[0.01, 1.0], [-0.01, -1.0]])
    cost = ((positions[:, None] - goals[None]) ** 2).sum(-1)
    gain = np.trace(cost) - (cost[0, 1] + cost[1, 0])
    assert gain == pytest.approx(0.08)
    np.testing.assert_array_equal(match_slots(positions, goals, hysteresis=0.1), [0, 1])
    np.testing.assert_array_equal(match_slots(positions, goals, hysteresis=0.05), [1, 0])
    assert SLOT_HYSTERESIS == 0.05


@pytest.mark.parametrize("seed", range(5))
def test_matching_is_the_least_total_squared_distance(seed):
    rng = np.random.default_rng(seed)
    positions, goals = rng.uniform(-3, 3, (6, 2)), rng.uniform(-3, 3, (6, 2))
    order = match_slots(positions, goals, hysteresis=0.0)
    assert sorted(order) == list(range(6))
    total = ((positions - goals[order]) ** 2).sum()
    best = min(((positions - goals[list(p)]) ** 2).sum() for p in itertools.permutations(range(6)))
    assert total == pytest.approx(best, rel=1e-12)


def test_bad_shapes():
    with pytest.raises(ValueError, match=r"both be \(M, 2\)"):
        match_slots(np.zeros((3, 2)), np.zeros((2, 2)))
    np.testing.assert_array_equal(match_slots(np.zeros((1, 2)), np.ones((1, 2))), [0])


def _swapped() -> Layout:
    """Two robots standing on each other's goals, no humans."""
    return Layout(
        robot_starts=np.array([[0.0, 0.0], [3.0, 0.0]]),
        robot_goals=np.array([[3.0, 0.0], [0.0, 0.0]]),
        human_starts=np.zeros((0, 2)),
        human_goals=np.zeros((0, 2)),
    )


def test_slots_let_robots_on_each_others_goals_succeed_at_once():
    fixed = CrowdEnv(EnvConfig())
    obs = fixed.reset_layout(_swapped())
    obs, done, _ = fixed.step(np.zeros((2, 2)))
    assert not done and not obs.robot_reached.any()
    np.testing.assert_array_equal(obs.robot_goals, [[3.0, 0.0], [0.0, 0.0]])

    slots = CrowdEnv(EnvConfig(goal_assignment="slots"))
    obs = slots.reset_layout(_swapped())
    np.testing.assert_array_equal(obs.robot_goals, [[3.0, 0.0], [0.0, 0.0]])  # as laid out until a step
    obs, done, info = slots.step(np.zeros((2, 2)))
    assert done and info["success"] and obs.robot_reached.all()
    np.testing.assert_array_equal(obs.robot_goals, [[0.0, 0.0], [3.0, 0.0]])
    np.testing.assert_array_equal(slots.trajectory().robot_goals, [[0.0, 0.0], [3.0, 0.0]])


def test_a_robot_whose_goal_changes_has_not_reached_the_new_one():
    # Robot 0 starts on goal 0; robot 1 at 0.1 m from goal 0 and 2.9 m from goal 1, robot 0 at 3 m from
    # goal 1: robot 0 keeps goal 0 (0 + 2.9^2 < 0.1^2 + 3^2), so nobody's goal changes.
    env = CrowdEnv(EnvConfig(goal_assignment="slots"))
    layout = Layout(
        robot_starts=np.array([[0.0, 0.0], [0.0, 0.1]]),
        robot_goals=np.array([[0.0, 0.0], [0.0, 3.0]]),
        human_starts=np.zeros((0, 2)),
        human_goals=np.zeros((0, 2)),
    )
    with pytest.warns(LayoutWarning, match=r"robot_starts\[0\] and robot_starts\[1\] 0.1 m apart"):
        obs = env.reset_layout(layout)  # in contact on purpose
    assert list(obs.robot_reached) == [True, False]
    obs, _, _ = env.step(np.zeros((2, 2)))
    np.testing.assert_array_equal(obs.robot_goals, layout.robot_goals)
    # Robot 0 drives off towards goal 1 at a_max: once it is nearer to goal 1 and robot 1 to goal 0 the goals
    # swap, and robot 0's reach of goal 0 no longer counts.
    for _ in range(6):
        obs, _, _ = env.step(np.array([[0.0, 1.0], [0.0, 0.0]]))
    np.testing.assert_array_equal(obs.robot_goals, [[0.0, 3.0], [0.0, 0.0]])
    assert list(obs.robot_reached) == [False, True]


def test_unknown_goal_assignment():
    with pytest.raises(SimulationError, match=r"goal_assignment must be one of \['fixed', 'slots'\]"):
        EnvConfig(goal_assignment="swap")  # type: ignore[arg-type]


def test_a_gain_equal_to_the_hysteresis_keeps_the_goals():
    # Goals (-1, 0) and (1, 0), robots at (0.25, 1) and (-0.25, -1): held, 2 x (1.25^2 + 1) = 5.125 m^2;
    # swapped, 2 x (0.75^2 + 1) = 3.125 m^2, a gain of exactly 2.0 (all binary fractions). The matching must
    # beat the current one by more than the hysteresis: 2.0 keeps the goals, 1.99 swaps them.
    goals = np.array([[-1.0, 0.0], [1.0, 0.0]])
    positions = np.array([[0.25, 1.0], [-0.25, -1.0]])
    np.testing.assert_array_equal(match_slots(positions, goals, hysteresis=2.0), [0, 1])
    np.testing.assert_array_equal(match_slots(positions, goals, hysteresis=1.99), [1, 0])


def test_points_must_be_2d():
    with pytest.raises(ValueError, match=r"both be \(M, 2\)"):
        match_slots(np.zeros((3, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"both be \(M, 2\)"):
        match_slots(np.zeros(2), np.zeros(2))


def test_slots_refuse_the_first_reach_rule():
    """Under first_reach the metrics judge each robot's reach against the goal it holds at the end, while the
    simulator forgets a reach when the slot changes hands: a timed-out episode could read as a success."""
    with pytest.raises(SimulationError, match="'slots' needs success_rule 'simultaneous'"):
        EnvConfig(goal_assignment="slots", success_rule="first_reach")
    EnvConfig(goal_assignment="slots")  # the paper profile's rule
