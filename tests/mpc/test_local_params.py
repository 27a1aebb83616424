"""The local NLPs' parameters built once per step, and C_i mapped over many plans: both must give exactly the
numbers of one vector and one call per robot (mpc/local_params.py, LocalNLP.costs)."""

import numpy as np
import pytest

from mpc.config import MPCConfig
from mpc.dynamics import rollout_numpy
from mpc.nlp import LocalNLP, StepData

CFG = MPCConfig(w_floc=7.0)
M, N, H = 4, 3, CFG.horizon


def _data(rng) -> StepData:
    states = np.concatenate([rng.uniform(-2, 2, (M, 2)), rng.uniform(-1, 1, (M, 2))], axis=1)
    return StepData(
        states=states,
        last_actions=rng.uniform(-2, 2, (M, 2)),
        goals=rng.uniform(-4, 4, (M, 2)),
        active=np.ones(M, bool),
        arrived=np.array([False, False, True, False]),  # robot 2 has arrived: its pairs do not flock
        human_margins=rng.uniform(0, 0.5, (H, N)),
        targets=rng.uniform(-4, 4, (M, 2)),
        goal_slack=np.array([0.0, 1.5, 0.0, 0.25]),
    )


def test_parameters_by_hand():
    """Robot 1 of 4: its own rows, the flocking weights of pairs (0,1), (1,2), (1,3), robots 0, 2, 3's plans,
    the margins and the predictions, in that order."""
    rng = np.random.default_rng(0)
    data = _data(rng)
    local = LocalNLP(CFG, M, N)
    positions, humans = rng.normal(size=(M, H, 2)), rng.normal(size=(H, N, 2))
    expected = np.concatenate(
        [
            data.states[1],
            data.last_actions[1],
            data.goals[1],
            data.targets[1],
            [1.5],
            [7.0, 0.0, 7.0],  # the pair with the arrived robot 2 does not flock
            positions[[0, 2, 3]].ravel(),
            data.human_margins.ravel(),
            humans.ravel(),
        ]
    )
    step = local.step_params(data)
    np.testing.assert_array_equal(step.row(1, positions, humans), expected)
    np.testing.assert_array_equal(local.params(1, data, positions, humans), expected)
    rows = step.rows(np.array([3, 1]), positions, humans)
    np.testing.assert_array_equal(rows[1], expected)
    np.testing.assert_array_equal(rows[0], step.row(3, positions, humans))
    assert rows.shape == (2, local.cost_fn.nnz_in(1))
    assert step.rows([], positions, humans).shape == (0, local.cost_fn.nnz_in(1))


def test_one_robot_has_no_others():
    data = StepData(np.zeros((1, 4)), np.zeros((1, 2)), np.ones((1, 2)), np.ones(1, bool))
    local = LocalNLP(CFG, 1, N)
    row = local.params(0, data, np.zeros((1, H, 2)), np.zeros((H, N, 2)))
    assert row.shape == (local.cost_fn.nnz_in(1),)


@pytest.mark.parametrize("n", [1, 2, 5])
def test_mapped_costs_equal_single_calls_bit_for_bit(n):
    """DMPC compares costs to epsilon and keeps plans on the result: the batched evaluation must not change
    a single bit of any C_i or penalty."""
    rng = np.random.default_rng(n)
    data = _data(rng)
    local = LocalNLP(CFG, M, N)
    step = local.step_params(data)
    accels = rng.uniform(-2, 2, (n, M, H, 2))
    robots = rng.integers(0, M, n)
    # Robots close to each other and to the humans, so the penalties are not all zero.
    humans = rng.uniform(-2, 2, (H, N, 2))
    plans = [accels[k, robots[k]] for k in range(n)]
    params = [
        step.row(int(robots[k]), rollout_numpy(data.states, accels[k], CFG.dt)[0], humans) for k in range(n)
    ]
    costs = local.costs(plans, params)
    penalties = local.penalties(plans, params)
    assert costs.shape == penalties.shape == (n,)
    assert np.array_equal(costs, [local.cost(a, q) for a, q in zip(plans, params, strict=True)])
    assert np.array_equal(penalties, [local.penalty(a, q) for a, q in zip(plans, params, strict=True)])
    assert np.all(np.isfinite(costs)) and penalties.max() > 0


def test_mapped_costs_check_their_inputs():
    local = LocalNLP(CFG, M, N)
    q = np.zeros(local.cost_fn.nnz_in(1))
    with pytest.raises(ValueError, match="2 plans but 1 parameter vectors"):
        local.costs([np.zeros((H, 2))] * 2, [q])
    assert local.costs([], []).shape == (0,)


def test_every_robots_flocking_weights_follow_its_pairs():
    """Robot i's flocking weights are those of its pairs (i, j), j != i in index order; robot 2 has arrived,
    so every pair with it has weight 0. Robot 0: (0,1), (0,2), (0,3); robot 3: (0,3), (1,3), (2,3)."""
    rng = np.random.default_rng(0)
    step = LocalNLP(CFG, M, N).step_params(_data(rng))
    positions, humans = np.zeros((M, H, 2)), np.zeros((H, N, 2))
    # state 4 + last action 2 + goal 2 + target 2 + slack 1 = 11 entries before the weights.
    weights = np.stack([step.row(i, positions, humans)[11 : 11 + M - 1] for i in range(M)])
    expected = [[7.0, 0.0, 7.0], [7.0, 0.0, 7.0], [0.0, 0.0, 0.0], [7.0, 7.0, 0.0]]
    np.testing.assert_array_equal(weights, expected)
