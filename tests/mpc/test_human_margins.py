"""Margins per human and step (StepData.human_margins): by hand in the cost, and through both NLPs."""

import math

import casadi as ca
import numpy as np
import pytest

from mpc import costs
from mpc.config import MPCConfig
from mpc.nlp import JointNLP, LocalNLP, StepData


def _sp(g: float, mu: float) -> float:
    return math.log1p(math.exp(mu * g)) / mu


def test_each_human_gets_its_own_margin_by_hand():
    """One step, the robot at the origin, humans 1 m and 3 m away: (d_min + m_j)^2 - d_j^2 inside smax."""
    cfg = MPCConfig(horizon=1)
    positions, velocities = ca.DM([[0.0], [0.0]]), ca.DM.zeros(2, 1)
    humans = ca.DM([[1.0, 3.0], [0.0, 0.0]])
    near_only = costs.human_collision_cost(positions, velocities, humans, 2, cfg, ca.DM([[0.5, 0.0]]))
    far_only = costs.human_collision_cost(positions, velocities, humans, 2, cfg, ca.DM([[0.0, 0.5]]))
    assert float(near_only) == pytest.approx(_sp(1.3**2 - 1, cfg.mu) + _sp(0.8**2 - 9, cfg.mu), rel=1e-12)
    assert float(far_only) == pytest.approx(_sp(0.8**2 - 1, cfg.mu) + _sp(1.3**2 - 9, cfg.mu), rel=1e-12)


def _data(margins=None) -> StepData:
    states = np.array([[-1.0, -3.0, 0.0, 0.5], [1.0, -3.0, 0.0, 0.5]])
    return StepData(states, np.zeros((2, 2)), states[:, :2] + [0.0, 6.0], np.ones(2, bool), None, margins)


def test_the_nlps_read_the_margins_from_the_step_data():
    cfg = MPCConfig(human_margins=(0.1, 0.2, 0.3, 0.4))
    h, n = cfg.horizon, 3
    rng = np.random.default_rng(0)
    prediction = rng.uniform(-2, 2, (h, n, 2))
    accels = rng.uniform(-1, 1, (2, h, 2))
    joint = JointNLP(cfg, 2, n)
    broadcast = np.repeat(np.array(cfg.human_margins)[:, None], n, axis=1)
    # The configured margins and the same margins given per human are one NLP, bit for bit.
    assert joint.potential(accels, _data(), prediction) == joint.potential(
        accels, _data(broadcast), prediction
    )
    # A margin on one human only: the penalty lies between none and that margin on everyone.
    one = np.zeros((h, n))
    one[:, 0] = 0.4
    penalties = [joint.penalty(accels, _data(m), prediction) for m in (np.zeros((h, n)), one, one * 0 + 0.4)]
    assert penalties[0] < penalties[1] < penalties[2]
    local = LocalNLP(cfg, 2, n)
    positions = rng.uniform(-2, 2, (2, h, 2))
    q_cfg = local.params(0, _data(), positions, prediction)
    q_given = local.params(0, _data(broadcast), positions, prediction)
    np.testing.assert_array_equal(q_cfg, q_given)
    assert local.penalty(accels[0], local.params(0, _data(one), positions, prediction)) <= local.penalty(
        accels[0], q_given
    )


@pytest.mark.parametrize("bad", [np.zeros((4, 2)), np.full((4, 3), -0.1), np.full((4, 3), np.nan)])
def test_bad_margins_are_refused(bad):
    joint = JointNLP(MPCConfig(), 2, 3)
    with pytest.raises(ValueError, match=r"human_margins must be finite metres >= 0 of shape \(4, 3\)"):
        joint.params(_data(bad), np.zeros((4, 3, 2)))


def test_the_reference_heads_for_the_targets_and_the_goal_weight_keeps_the_goal():
    """Eq. 8's reference heads for ``targets``; with the goals as targets the NLP is the paper's, exactly."""
    cfg = MPCConfig()
    joint = JointNLP(cfg, 2, 1)
    data, prediction = _data(), np.full((cfg.horizon, 1, 2), 9.0)
    accels = np.zeros((2, cfg.horizon, 2))
    same = StepData(data.states, data.last_actions, data.goals, data.active, None, None, data.goals.copy())
    assert joint.potential(accels, same, prediction) == joint.potential(accels, data, prediction)
    # Robot 0 stands still at (-1, -3) with velocity (0, 0.5): heading east instead of north costs more for a
    # plan that keeps going north, and the goal's distance weight (Eq. 7) is the same.
    east = data.goals.copy()
    east[0] = [5.0, -3.0]
    turned = StepData(data.states, data.last_actions, data.goals, data.active, None, None, east)
    assert joint.potential(accels, turned, prediction) > joint.potential(accels, data, prediction)
    with pytest.raises(ValueError, match=r"targets must be finite positions of shape \(2, 2\)"):
        joint.params(
            StepData(data.states, data.last_actions, data.goals, data.active, None, None, east[:1]),
            prediction,
        )


def test_the_objectives_see_the_margins_as_the_penalties_do():
    """The margins enter what the solvers minimise, not only the reported penalty: only the collision terms
    depend on them, so F(m) - F(0) = penalty(m) - penalty(0), and likewise C_i for a local NLP."""
    cfg = MPCConfig()
    h, n = cfg.horizon, 2
    # Each robot walks with a human 0.9 m east of it: inside d_min + 0.4 = 1.2 m, outside d_min = 0.8 m, so
    # a 0.4 m margin changes the penalty by ~1e7 * 0.7 per such pair and step.
    data = _data()
    accels = np.zeros((2, h, 2))
    steps = cfg.dt * np.arange(1, h + 1)[:, None]
    positions = np.stack([data.states[i, :2] + data.states[i, 2:] * steps for i in range(2)])  # (M, H, 2)
    # Human n walks 0.9 m east of robot n: (H, N_h, 2).
    prediction = positions.transpose(1, 0, 2) + [0.9, 0.0]
    zero, wide = _data(np.zeros((h, n))), _data(np.full((h, n), 0.4))
    joint = JointNLP(cfg, 2, n)
    d_penalty = joint.penalty(accels, wide, prediction) - joint.penalty(accels, zero, prediction)
    assert d_penalty > 1e6
    d_potential = joint.potential(accels, wide, prediction) - joint.potential(accels, zero, prediction)
    assert d_potential == pytest.approx(d_penalty, rel=1e-9)
    local = LocalNLP(cfg, 2, n)
    q_zero, q_wide = (local.params(0, d, positions, prediction) for d in (zero, wide))
    d_penalty = local.penalty(accels[0], q_wide) - local.penalty(accels[0], q_zero)
    assert d_penalty > 1e6
    assert local.cost(accels[0], q_wide) - local.cost(accels[0], q_zero) == pytest.approx(d_penalty, rel=1e-9)
