"""Algorithm 1 (CMPC) on hand-made inputs."""

import numpy as np
import pytest

from mpc.cmpc import CMPC
from mpc.config import MPCConfig
from mpc.dynamics import braking, rollout_numpy
from mpc.fallback import PlanMemory
from mpc.nlp import StepData
from predictors.base import DT
from tests.mpc.loop import drive
from tests.mpc.reactive import ReactivePredictor


def crossing_data():
    """Three robots heading north side by side at rest, goals 6 m ahead."""
    states = np.array([[-1.2, -3.0, 0, 0], [0.0, -3.0, 0, 0], [1.2, -3.0, 0, 0]], dtype=float)
    goals = states[:, :2] + [0.0, 6.0]
    return StepData(states, np.zeros((3, 2)), goals, np.ones(3, dtype=bool))


def no_humans(cfg):
    return lambda robots_future: np.zeros((cfg.horizon, 0, 2))


def test_two_robots_without_humans_reach_their_goals():
    cfg = MPCConfig()
    states = np.array([[-0.6, -3.0, 0, 0], [0.6, -3.0, 0, 0]], dtype=float)
    goals = np.array([[-0.6, 3.0], [0.6, 3.0]])
    final = drive(CMPC(cfg, 2, 0), states, goals, steps=40)
    assert np.all(np.linalg.norm(final[:, :2] - goals, axis=1) < 0.3)


def test_fixed_predictions_converge_at_the_second_iteration_without_a_second_solve():
    """A prediction equal to the previous one is a fixed point: the same NLP is not solved again."""
    cfg = MPCConfig(multi_start=False)
    data = crossing_data()
    humans = np.tile([[0.0, 2.0], [3.0, 0.0]], (cfg.horizon, 1, 1))
    calls = []

    def predict(robots_future):
        calls.append(robots_future)
        return humans

    start = PlanMemory(cfg).start(data)
    result = CMPC(cfg, 3, 2).solve(data, predict, start)
    assert result.solved and result.converged and result.status == "ok"
    assert (result.iterations, result.solves, len(calls)) == (2, 1, 2)
    # The second prediction was asked for the robots' planned positions of iteration 1.
    np.testing.assert_allclose(calls[1], result.positions.transpose(1, 0, 2))
    assert result.potential == pytest.approx(CMPC(cfg, 3, 2).nlp.potential(result.accels, data, humans))


def test_reacting_humans_need_several_iterations_and_the_loop_stops_on_xi():
    cfg = MPCConfig()
    data = crossing_data()
    predictor = ReactivePredictor(gain=0.3)
    # Two humans walking south towards the robots, observed over two steps (robots first in the history).
    now = np.concatenate([data.states[:, :2], [[-0.5, 0.0], [0.7, 0.5]]])
    history = np.stack([now + [0.0, DT * 1.0] * (np.arange(5) >= 3)[:, None], now])
    mask = np.ones(history.shape[:2], dtype=bool)
    humans = np.array([3, 4])

    def predict(robots_future):
        return predictor.rollout(history, mask, robots_future, humans)

    solver = CMPC(cfg, 3, 2)
    result = solver.solve(data, predict, PlanMemory(cfg).start(data))
    assert result.solved and result.converged and 2 < result.iterations < cfg.j_max
    assert len(result.predictions) == len(result.potentials) == result.iterations
    # Stopped by the test of Algorithm 1, and not earlier.
    steps = np.abs(np.diff(result.potentials))
    assert steps[-1] <= cfg.xi and np.all(steps[:-1] > cfg.xi)
    # The prediction returned is the one the plan was optimised against.
    np.testing.assert_array_equal(result.prediction, result.predictions[-1])


def test_solution_respects_the_bounds_of_eq6():
    cfg = MPCConfig()
    data = crossing_data()
    result = CMPC(cfg, 3, 0).solve(data, no_humans(cfg), PlanMemory(cfg).start(data))
    tol = 1e-6
    assert np.abs(result.accels).max() <= cfg.a_max + tol
    velocities = rollout_numpy(data.states, result.accels, cfg.dt)[1]
    assert np.abs(velocities).max() <= cfg.v_max + tol


def test_parked_robot_is_pinned_to_braking():
    cfg = MPCConfig()
    base = crossing_data()
    states = base.states.copy()
    states[1, 2:] = [0.3, -0.5]  # the middle robot has arrived but still moves
    data = StepData(states, base.last_actions, base.goals, np.array([True, False, True]))
    result = CMPC(cfg, 3, 0).solve(data, no_humans(cfg), PlanMemory(cfg).start(data))
    np.testing.assert_allclose(result.accels[1], braking(states[1:2], cfg.horizon, cfg.dt, cfg.a_max)[0])
    assert np.abs(result.accels[0]).max() > 0.1  # the others still drive
