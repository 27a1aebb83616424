"""Algorithm 2 (DMPC): the epsilon rule, the epsilon-Nash stop, and reaching goals."""

import dataclasses

import numpy as np
import pytest

from mpc.cmpc import CMPC
from mpc.config import DMPC_UPDATES, MPCConfig
from mpc.dmpc import DMPC
from mpc.dmpc_keep import accept
from mpc.dynamics import braking, rollout_numpy
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
    assert accept(9.0, 10.0, 1.0)  # exactly epsilon better (exact in binary): "at least epsilon" keeps it


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


@pytest.mark.parametrize("update", DMPC_UPDATES)
def test_a_failed_local_solve_does_not_fail_a_step_that_solved(monkeypatch, update):
    # Robot 1 fails, robot 0 solves: with Gauss-Seidel robot 1 is the last of the sweep, whose failure must
    # not hide robot 0's success.
    cfg = MPCConfig(dmpc_update=update)
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


def test_a_step_in_which_every_solve_fails_never_converges():
    """No robot keeps a new plan when every solve fails, but that is no epsilon-Nash equilibrium: the loop
    runs on to j_max and the step reports the failure."""
    cfg = MPCConfig(solver_max_iter=0, dmpc_stop="no_improvement", j_max=3)
    data = data_two_robots()
    result = DMPC(cfg, 2, 0).solve(data, no_humans(cfg), PlanMemory(cfg).start(data))
    assert not result.solved and not result.converged
    assert result.iterations == 3 and result.status == "Maximum_Iterations_Exceeded"


def test_the_epsilon_nash_check_holds_only_when_every_robot_passes():
    """Lines 12-16 on plans made by hand: robot 0 keeps its plan (passes), robot 1's new plan accelerates away
    from its goal at 1 m/s^2 (its C_i rises by far more than epsilon): not at an equilibrium. With both
    plans unchanged it is."""
    cfg = MPCConfig()
    data = data_two_robots()
    solver = DMPC(cfg, 2, 0)
    step = solver.local.step_params(data)
    moving, nobody = np.arange(2), np.zeros((cfg.horizon, 0, 2))
    old = np.zeros((2, cfg.horizon, 2))
    new = old.copy()
    new[1, :, 1] = -1.0
    new_positions = rollout_numpy(data.states, new, cfg.dt)[0]
    assert not solver._at_nash(step, moving, old, new, new_positions, nobody)
    old_positions = rollout_numpy(data.states, old, cfg.dt)[0]
    assert solver._at_nash(step, moving, old, old, old_positions, nobody)


def test_the_time_limit_ends_the_loop_after_the_iteration_that_passes_it():
    cfg = MPCConfig(time_limit_s=1e-9)
    data = data_two_robots()
    result = DMPC(cfg, 2, 0).solve(data, no_humans(cfg), PlanMemory(cfg).start(data))
    assert result.iterations == 1 and result.status == "timeout"


def _copy(a):
    return None if a is None else np.array(a)


def test_the_first_solves_warm_start_explore_and_restart_as_the_start_asks():
    """Iteration 1 from a shifted start: each robot's solve is warm-started with its own shifted multipliers;
    robot 0, which stands on a human (penalty far above restart_penalty), solves again from braking without
    multipliers (multi_start). From a braking start the first solves explore instead, and later ones don't."""
    cfg = MPCConfig(j_max=2)
    data = data_two_robots()

    def human_on_robot_0(robots_future):
        return np.tile(data.states[None, :1, :2], (cfg.horizon, 1, 1))

    solver = DMPC(cfg, 2, 1)
    real_solve, calls = solver.local.solve, []

    def recording(i, params, accels0, lam_x0=None, lam_g0=None, explore=False):
        # copies: the loop later writes kept plans' multipliers into the arrays these are views of
        calls.append((int(i), accels0.copy(), _copy(lam_x0), _copy(lam_g0), explore))
        return real_solve(i, params, accels0, lam_x0, lam_g0, explore)

    solver.local.solve = recording  # type: ignore[method-assign]
    lam_x = np.arange(2 * cfg.horizon * 2, dtype=float).reshape(2, cfg.horizon, 2)
    shifted = Start(np.zeros((2, cfg.horizon, 2)), "shifted", lam_x, -lam_x)
    solver.solve(data, human_on_robot_0, shifted)
    assert [c[0] for c in calls[:3]] == [0, 1, 0]
    for i in (0, 1):
        np.testing.assert_array_equal(calls[i][2], lam_x[i])
        np.testing.assert_array_equal(calls[i][3], -lam_x[i])
    restart = calls[2]
    np.testing.assert_array_equal(restart[1], braking(data.states, cfg.horizon, cfg.dt, cfg.a_max)[0])
    assert restart[2] is None and restart[3] is None
    assert not any(c[4] for c in calls)
    calls.clear()
    solver.solve(data, human_on_robot_0, PlanMemory(cfg).start(data))
    assert [c[4] for c in calls[:2]] == [True, True]  # braking start: both solvers on the first solves
    assert not any(c[4] for c in calls[2:]) and len(calls) > 2


def test_a_restart_keeps_the_lower_cost_of_the_two_solutions(monkeypatch):
    """multi_start keeps whichever of the first solution and the one from braking costs less (C_i)."""
    cfg = MPCConfig()
    data = data_two_robots()
    solver = DMPC(cfg, 2, 1)
    on_robot_0 = np.tile(data.states[None, :1, :2], (cfg.horizon, 1, 1))
    params = {i: solver.local.params(i, data, np.zeros((2, cfg.horizon, 2)), on_robot_0) for i in (0, 1)}
    first = solver.local.solve(0, params[0], np.zeros((cfg.horizon, 2)))
    assert first.success and solver.local.penalty(first.accels, params[0]) > cfg.restart_penalty
    # The solve from braking (faked) costs 1 more, then 1 less, than the first solution.
    for shift, keeps_first in ((1.0, True), (-1.0, False)):
        other = dataclasses.replace(first, accels=first.accels + 0.01, cost=first.cost + shift)
        monkeypatch.setattr(solver.local, "solve", lambda *args, other=other: other)
        out, extra = solver._restart(data, np.array([0]), params, [first])
        assert len(extra) == 1 and extra[0] is other
        assert out[0] is (first if keeps_first else other)


def test_each_iteration_predicts_the_humans_for_the_plans_of_the_previous_one():
    """Algorithm 2, line 2: iteration j predicts from the robots' plans of iteration j-1, given to the
    predictor as (H, M, 2). The predictor here depends on those plans (one human 3 m east of robot 0's), as a
    learned one does: iteration 1 predicts for u^(0), iteration 2 for the plans a 1-iteration run returns."""
    cfg = MPCConfig(j_max=3)
    data = data_two_robots()
    calls = []

    def predict(robots_future):
        calls.append(np.array(robots_future))
        return robots_future[:, :1] + [3.0, 0.0]

    start = PlanMemory(cfg).start(data)
    result = DMPC(cfg, 2, 1).solve(data, predict, start)
    assert result.iterations >= 2 and len(calls) == result.iterations == len(result.predictions)
    for call, prediction in zip(calls, result.predictions, strict=True):
        assert call.shape == (cfg.horizon, 2, 2)
        np.testing.assert_array_equal(prediction, call[:, :1] + [3.0, 0.0])
    first = rollout_numpy(data.states, start.accels, cfg.dt)[0].transpose(1, 0, 2)
    np.testing.assert_array_equal(calls[0], first)
    one = DMPC(cfg.replace(j_max=1), 2, 1).solve(data, predict, start)  # appends to calls after [1]
    np.testing.assert_array_equal(calls[1], one.positions.transpose(1, 0, 2))


def test_an_iteration_in_which_every_solve_fails_keeps_the_last_solved_prediction():
    """Iteration 1 solves, iteration 2's solves all fail (faked): the step returns iteration 1's plans, with
    the prediction they were optimised against (iteration 1's, not iteration 2's, which was made for other
    plans) and F under that prediction."""
    cfg = MPCConfig(j_max=2)
    data = data_two_robots()
    solver = DMPC(cfg, 2, 1)
    real_solve, count = solver.local.solve, []

    def fails_after_iteration_1(i, *args):
        count.append(i)
        sol = real_solve(i, *args)
        return sol if len(count) <= 2 else dataclasses.replace(sol, status="Fatrop_Failed", success=False)

    solver.local.solve = fails_after_iteration_1  # type: ignore[method-assign]

    def predict(robots_future):
        # Depends on the plans: one human 0.9 m west of robot 0's plan, near enough for its penalty to differ
        # between the two iterations' predictions.
        return robots_future[:, :1] - [0.9, 0.0]

    result = solver.solve(data, predict, PlanMemory(cfg).start(data))
    assert result.iterations == 2 and result.solved and not result.converged
    first, second = result.predictions
    f_first, f_second = (solver.joint.potential(result.accels, data, p) for p in (first, second))
    assert abs(f_second - f_first) > 1.0
    np.testing.assert_array_equal(result.prediction, first)
    assert result.potential == solver.joint.potential(result.accels, data, first)
