"""Algorithm 2 (DMPC): the epsilon rule, the epsilon-Nash stop, and reaching goals."""

import numpy as np
import pytest

from mpc.cmpc import CMPC
from mpc.config import MPCConfig
from mpc.dmpc import DMPC
from mpc.dmpc_keep import accept
from mpc.fallback import PlanMemory, Start
from mpc.nlp import StepData
from tests.mpc.loop import drive


def no_humans(cfg):
    return lambda robots_future: np.zeros((cfg.horizon, 0, 2))


def data_two_robots():
    states = np.array([[-0.6, -3.0, 0, 0], [0.6, -3.0, 0, 0]], dtype=float)
    return StepData(states, np.zeros((2, 2)), states[:, :2] + [0.0, 6.0], np.ones(2, dtype=bool))


def test_accept_requires_an_improvement_of_epsilon():
    assert accept(9.998, 10.0, 1e-3)
    assert not accept(9.9995, 10.0, 1e-3)  # better, but by less than epsilon
    assert not accept(10.5, 10.0, 1e-3)


def test_a_plan_that_does_not_improve_by_epsilon_is_rejected():
    """From braking, every local solve improves C_i by far less than a huge epsilon: all are rejected."""
    cfg = MPCConfig(epsilon=1e9, multi_start=False)
    data = data_two_robots()
    start = PlanMemory(cfg).start(data)
    result = DMPC(cfg, 2, 0).solve(data, no_humans(cfg), start)
    assert result.solves == 2 and result.solved and result.converged
    np.testing.assert_array_equal(result.accels, start.accels)
    # The same problem with the paper's epsilon moves both robots.
    small = DMPC(MPCConfig(multi_start=False), 2, 0).solve(data, no_humans(cfg), start)
    assert np.abs(small.accels - start.accels).max() > 0.1


def test_an_equilibrium_start_is_kept_and_converges_in_one_iteration():
    """Starting at the joint optimum (a Nash equilibrium, Lemma 1), no robot can improve by epsilon."""
    cfg = MPCConfig(multi_start=False, solver_tol=1e-10)
    data = data_two_robots()
    optimum = CMPC(cfg, 2, 0).solve(data, no_humans(cfg), PlanMemory(cfg).start(data))
    start = Start(optimum.accels, "shifted", None, None)
    result = DMPC(cfg, 2, 0).solve(data, no_humans(cfg), start)
    assert result.iterations == 1 and result.converged
    np.testing.assert_array_equal(result.accels, optimum.accels)
    assert result.potential == pytest.approx(optimum.potential)


def test_two_robots_without_humans_reach_their_goals():
    cfg = MPCConfig()
    data = data_two_robots()
    final = drive(DMPC(cfg, 2, 0), data.states, data.goals, steps=40)
    assert np.all(np.linalg.norm(final[:, :2] - data.goals, axis=1) < 0.3)


def test_threaded_local_solves_give_the_serial_result():
    data = data_two_robots()
    results = []
    for mode in ("serial", "threads"):
        cfg = MPCConfig(dmpc_parallel=mode)
        solver = DMPC(cfg, 2, 0)
        results.append(solver.solve(data, no_humans(cfg), PlanMemory(cfg).start(data)))
        solver.close()
    np.testing.assert_allclose(results[0].accels, results[1].accels, atol=1e-12)
    assert results[0].iterations == results[1].iterations


def test_close_stops_the_threads_and_a_later_solve_starts_them_again():
    cfg = MPCConfig(dmpc_parallel="threads")
    data = data_two_robots()
    solver = DMPC(cfg, 2, 0)
    first = solver.solve(data, no_humans(cfg), PlanMemory(cfg).start(data))
    solver.close()
    assert solver._pool is None
    again = solver.solve(data, no_humans(cfg), PlanMemory(cfg).start(data))
    assert solver._pool is not None
    solver.close()
    np.testing.assert_allclose(first.accels, again.accels, atol=1e-12)


def test_a_failed_local_solve_does_not_fail_a_step_that_solved(monkeypatch):
    cfg = MPCConfig()
    data = data_two_robots()
    solver = DMPC(cfg, 2, 0)
    real_solve = solver.local.solve

    def robot_1_fails(i, *args):
        sol = real_solve(i, *args)
        return (
            sol
            if i == 0
            else type(sol)(**{**sol.__dict__, "status": "Invalid_Number_Detected", "success": False})
        )

    monkeypatch.setattr(solver.local, "solve", robot_1_fails)
    result = solver.solve(data, no_humans(cfg), PlanMemory(cfg).start(data))
    assert result.solved and result.status == "ok"
