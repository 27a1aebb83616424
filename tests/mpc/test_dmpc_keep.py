"""Which best responses a DMPC iteration keeps (mpc/dmpc_keep.py), on plans given by hand: the order of the
sequential-accept update, the relaxed step, and the multipliers of the kept plans."""

import numpy as np

from mpc.config import MPCConfig
from mpc.dmpc_keep import PlanKeeper
from mpc.dynamics import rollout_numpy
from mpc.fallback import heading_plan
from mpc.nlp import LocalNLP, StepData
from mpc.solvers import Solution

# No flocking: the two robots below interact only through the robot-robot collision penalty.
CFG = MPCConfig(w_floc=0.0)


def _setup(cfg: MPCConfig):
    """Robots at rest at (-0.5, 0) and (2, 0), both heading for (1, 0); their plans of iteration j-1 are
    braking (zeros). Returns the keeper, the step's parameters, each robot's parameters against the old
    plans, the old plans and the plans heading straight for (1, 0), which end 0.02 m apart."""
    states = np.array([[-0.5, 0.0, 0.0, 0.0], [2.0, 0.0, 0.0, 0.0]])
    data = StepData(states, np.zeros((2, 2)), np.array([[1.0, 0.0], [1.0, 0.0]]), np.ones(2, bool))
    local = LocalNLP(cfg, 2, 0)
    step = local.step_params(data)
    old = np.zeros((2, cfg.horizon, 2))
    rows = step.rows(np.arange(2), rollout_numpy(states, old, cfg.dt)[0], np.zeros((cfg.horizon, 0, 2)))
    return PlanKeeper(cfg, local, 2), step, dict(enumerate(rows)), old, heading_plan(data, cfg)


def _solution(accels, cost, lam=0.0):
    lam_x = np.full(accels.size, lam)
    return Solution(accels, cost, "Solve_Succeeded", True, 1, "fatrop", lam_x, -lam_x)


def test_sequential_accept_keeps_the_largest_improvement_first():
    """Each heading plan improves its robot's C_i against the other's old plan (robot 0, 1.5 m from the goal,
    by more than robot 1, 1 m from it), but together they collide. Robot 0's is kept first; robot 1's,
    re-checked against it, no longer improves and is rejected."""
    keeper, step, params, old, plans = _setup(CFG)
    local = keeper.local
    sols = [_solution(plans[i], local.cost(plans[i], params[i])) for i in range(2)]
    gains = [local.cost(old[i], params[i]) - sols[i].cost for i in range(2)]
    assert gains[0] > gains[1] > 1.0
    prediction = np.zeros((CFG.horizon, 0, 2))
    kept, _, _, failure = keeper.in_turn(step, np.arange(2), params, prediction, old, sols, None, None)
    np.testing.assert_array_equal(kept[0], plans[0])
    np.testing.assert_array_equal(kept[1], old[1])
    assert failure == ""


def test_kept_plans_bring_their_own_multipliers():
    """Jacobi keeps both heading plans (each improves against the other's old plan); the multipliers are
    made on the first kept plan and each robot's row is its own solve's."""
    keeper, _, params, old, plans = _setup(CFG)
    sols = [_solution(plans[i], keeper.local.cost(plans[i], params[i]), lam=2.0 + i) for i in range(2)]
    kept, lam_x, lam_g, _ = keeper.improvements(np.arange(2), params, old, sols, None, None)
    np.testing.assert_array_equal(kept, plans)
    np.testing.assert_array_equal(lam_x, np.array([2.0, 3.0])[:, None, None] * np.ones_like(old))
    np.testing.assert_array_equal(lam_g, -lam_x)


def test_a_relaxed_step_goes_alpha_of_the_way_and_is_kept_only_if_it_improves():
    """alpha = 0.5 from braking (zeros): robot 0's candidate is half its heading plan, which still improves
    its C_i and is kept. Robot 1's best response is (faked as) a plan away from its goal: half of it is
    worse than braking, so braking stays."""
    cfg = CFG.replace(dmpc_update="relaxed", dmpc_relaxation=0.5)
    keeper, _, params, old, plans = _setup(cfg)
    away = -plans[1]
    sols = [
        _solution(plans[0], 0.0),
        _solution(away, 0.0),
    ]  # the relaxed rule evaluates the candidates itself
    kept, _, _, _ = keeper.relaxed(np.arange(2), params, old, sols, None, None)
    np.testing.assert_array_equal(kept[0], 0.5 * plans[0])
    np.testing.assert_array_equal(kept[1], old[1])
    assert keeper.local.cost(0.5 * away, params[1]) > keeper.local.cost(old[1], params[1])
