"""A failing step never ends an episode: shifted previous plan, else braking; the status is recorded."""

import numpy as np

from mpc.cmpc import CMPC
from mpc.config import MPCConfig
from mpc.dmpc import DMPC
from mpc.dynamics import braking
from mpc.fallback import PlanMemory
from mpc.nlp import StepData


def moving_data():
    states = np.array([[0.0, 0.0, 0.5, 0.5], [2.0, 0.0, -0.5, 0.5]])
    return StepData(states, np.zeros((2, 2)), np.array([[0.0, 5.0], [2.0, 5.0]]), np.ones(2, dtype=bool))


def humans(cfg, value=0.0):
    return lambda robots_future: np.full((cfg.horizon, 1, 2), value) + [5.0, -5.0]


def test_forced_ipopt_failure_returns_the_start_and_its_status():
    cfg = MPCConfig(solver_max_iter=0)
    data = moving_data()
    start = PlanMemory(cfg).start(data)
    assert start.kind == "brake"
    for solver in (CMPC(cfg, 2, 1), DMPC(cfg, 2, 1)):
        result = solver.solve(data, humans(cfg), start)
        assert not result.solved
        assert result.status == "Maximum_Iterations_Exceeded"
        np.testing.assert_array_equal(result.accels, braking(data.states, cfg.horizon, cfg.dt, cfg.a_max))


def test_nan_prediction_is_a_failure_not_a_crash():
    cfg = MPCConfig()
    data = moving_data()
    start = PlanMemory(cfg).start(data)
    for solver in (CMPC(cfg, 2, 1), DMPC(cfg, 2, 1)):
        result = solver.solve(data, humans(cfg, np.nan), start)
        assert not result.solved and result.status == "nan_prediction" and result.solves == 0


def test_timeout_is_a_failure():
    cfg = MPCConfig(time_limit_s=1e-9)
    data = moving_data()
    result = CMPC(cfg, 2, 1).solve(data, humans(cfg), PlanMemory(cfg).start(data))
    assert not result.solved and result.status == "Maximum_WallTime_Exceeded"


def test_shifted_plan_then_braking_after_the_solved_actions_run_out():
    cfg = MPCConfig()
    data = moving_data()
    memory = PlanMemory(cfg)
    plan = np.zeros((2, cfg.horizon, 2))
    plan[:, :, 1] = [[0.1, 0.2, 0.3, 0.4], [-0.1, -0.2, -0.3, -0.4]]  # small: within Eq. 6 from data.states
    memory.commit(plan, solved=True)
    kinds = []
    for k in range(1, cfg.horizon + 1):
        start = memory.start(data)
        kinds.append(start.kind)
        if start.kind == "shifted":
            np.testing.assert_allclose(start.accels[:, 0], plan[:, k])  # the action planned for this step
            np.testing.assert_allclose(start.accels[:, -1], 0.0)  # padding keeps the velocity
        else:
            np.testing.assert_allclose(start.accels, braking(data.states, cfg.horizon, cfg.dt, cfg.a_max))
        memory.commit(start.accels, solved=False)
    # A horizon-4 plan covers 3 further steps; the 4th failing step brakes.
    assert kinds == ["shifted", "shifted", "shifted", "brake"]


def test_shifted_plan_is_clipped_to_the_bounds_from_the_current_state():
    cfg = MPCConfig()
    memory = PlanMemory(cfg)
    memory.commit(np.full((1, cfg.horizon, 2), 2.0), solved=True)  # full acceleration, planned from rest
    data = StepData(np.array([[0.0, 0.0, 0.9, -0.9]]), np.zeros((1, 2)), np.ones((1, 2)), np.ones(1, bool))
    start = memory.start(data)
    # v_x = 0.9 leaves (1 - 0.9) / 0.4 = 0.25 of acceleration; v_y = -0.9 leaves the full 2.0.
    np.testing.assert_allclose(start.accels[0, 0], [0.25, 2.0])
