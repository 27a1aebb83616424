"""Fatrop and IPOPT behind mpc.nlp: same solutions, and IPOPT catching what Fatrop fails."""

import numpy as np
import pytest

from mpc.config import MPCConfig
from mpc.nlp import JointNLP, LocalNLP, StepData


def crossing_data():
    """Three robots heading north at walking speed, goals 6 m ahead, a human walking south between them."""
    states = np.array([[-1.2, -3.0, 0, 0.8], [0.0, -3.0, 0, 0.8], [1.2, -3.0, 0, 0.8]], dtype=float)
    goals = states[:, :2] + [0.0, 6.0]
    return StepData(states, np.zeros((3, 2)), goals, np.ones(3, dtype=bool))


def human_walking_south(cfg, x=0.3):
    steps = np.arange(1, cfg.horizon + 1)[:, None] * cfg.dt
    return np.stack([np.full(cfg.horizon, x), -1.2 - 1.0 * steps[:, 0]], axis=1)[:, None, :]


def test_fatrop_and_ipopt_find_the_same_joint_solution_from_a_warm_start():
    data = crossing_data()
    humans = human_walking_south(MPCConfig())
    solutions = {}
    for solver in ("fatrop", "ipopt"):
        cfg = MPCConfig(solver=solver)
        nlp = JointNLP(cfg, 3, 1)
        # From braking a little. (From standing on the gas the start breaks the velocity bound; Fatrop then
        # fails and the IPOPT retry solves it, see below.)
        accels0 = np.tile([0.0, -0.5], (3, cfg.horizon, 1))
        solutions[solver] = nlp.solve(data, humans, accels0)
    fatrop, ipopt = solutions["fatrop"], solutions["ipopt"]
    assert fatrop.success and fatrop.solver == "fatrop" and ipopt.success and ipopt.solver == "ipopt"
    assert fatrop.cost == pytest.approx(ipopt.cost, rel=1e-6)
    np.testing.assert_allclose(fatrop.accels, ipopt.accels, atol=1e-4)
    # The human at x = 0.3 m pushes the middle robot aside: the solution is not the trivial straight drive.
    assert abs(fatrop.accels[1, :, 0]).max() > 0.1


def test_fatrop_and_ipopt_find_the_same_local_solution():
    data = crossing_data()
    cfg = MPCConfig()
    humans = human_walking_south(cfg)
    positions = np.stack([data.states[:, :2] + [0, 0.8 * cfg.dt * (k + 1)] for k in range(cfg.horizon)], 1)
    costs = []
    for solver in ("fatrop", "ipopt"):
        local = LocalNLP(MPCConfig(solver=solver), 3, 1)
        params = local.params(1, data, positions, humans)
        sol = local.solve(1, params, np.zeros((cfg.horizon, 2)))
        assert sol.success and sol.solver == solver
        # The cost the solver reports is C_i of the plan it returns.
        assert local.cost(sol.accels, params) == pytest.approx(sol.cost, rel=1e-9)
        costs.append(sol.cost)
    assert costs[0] == pytest.approx(costs[1], rel=1e-6)


class FailingFatrop:
    """Stands in for the buffered Fatrop: returns garbage and says it failed after 7 iterations."""

    def __init__(self, n):
        self.n, self.calls = n, 0

    def call(self, args):
        self.calls += 1
        nan = np.full(self.n, np.nan)
        return {"x": nan, "f": np.array([np.nan]), "lam_x": nan, "lam_g": nan}

    def stats(self):
        return {"success": False, "iter_count": 7}


def test_a_failed_fatrop_solve_is_retried_with_ipopt():
    cfg = MPCConfig()
    nlp = JointNLP(cfg, 3, 1)
    stub = FailingFatrop(3 * cfg.horizon * 2)
    nlp._solver()._fatrop = stub
    sol = nlp.solve(crossing_data(), human_walking_south(cfg), np.zeros((3, cfg.horizon, 2)))
    assert stub.calls == 1
    assert sol.success and sol.solver == "ipopt" and sol.status == "Solve_Succeeded"
    assert sol.iterations > 7 and np.all(np.isfinite(sol.accels))


def test_ipopt_only_settings_make_ipopt_the_solver():
    """The coupled NLP's L-BFGS option is IPOPT's: such an NLP never goes to Fatrop."""
    cfg = MPCConfig()

    class LbfgsModel:
        n_params = 2 * cfg.horizon
        ipopt_options = {"ipopt.hessian_approximation": "limited-memory"}

        def humans(self, p, robots_future):
            return p

    nlp = JointNLP(cfg, 3, 1, humans_model=LbfgsModel())
    assert nlp._solver().primary == "ipopt"
    assert JointNLP(cfg, 3, 1)._solver().primary == "fatrop"
    assert JointNLP(MPCConfig(solver="ipopt"), 3, 1)._solver().primary == "ipopt"
