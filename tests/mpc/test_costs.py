"""Each cost term of Section IV against a value computed by hand, and Lemma 1 numerically."""

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest

from mpc import costs
from mpc.config import MPCConfig
from mpc.dynamics import rollout_numpy
from mpc.nlp import JointNLP, LocalNLP, StepData

CFG = MPCConfig()


def value(x) -> float:
    return float(ca.DM(x))


def test_smax_by_hand():
    assert value(costs.smax(ca.DM(0.0), 30.0)) == pytest.approx(math.log(2) / 30)
    assert value(costs.smax(ca.DM(0.05), 30.0)) == pytest.approx(math.log(math.exp(1.5) + 1) / 30)
    assert value(costs.smax(ca.DM(1.0), 30.0)) == pytest.approx(1.0 + math.log1p(math.exp(-30)) / 30)
    assert value(costs.smax(ca.DM(-1.0), 30.0)) == pytest.approx(math.log1p(math.exp(-30)) / 30, rel=1e-12)
    # Far beyond any overflow of exp(mu z): the stable form stays finite and equal to z.
    assert value(costs.smax(ca.DM(100.0), 30.0)) == pytest.approx(100.0)


def test_smooth_norm_by_hand():
    np.testing.assert_allclose(costs.smooth_norm(ca.DM([[3, 0], [4, 0]]), 0.0).full(), [[5.0, 0.0]])
    assert value(costs.smooth_norm(ca.DM([3, 4]), 1e-3)) == pytest.approx(math.sqrt(25.001))


def test_reference_trajectory_moves_at_v_max_and_stops_on_the_goal():
    # tau v_max = 0.4 m per step towards a goal 1 m away: 0.4, 0.8, then the remaining 0.2, then stay.
    ref = costs.reference_trajectory(ca.DM([0, 0]), ca.DM([0, 1]), 4, 0.4, 1.0)
    np.testing.assert_allclose(ref.full(), [[0, 0, 0, 0], [0.4, 0.8, 1.0, 1.0]], atol=1e-12)
    # Along (3, 4) / 5: 0.4 * (0.6, 0.8) = (0.24, 0.32) per step.
    ref = costs.reference_trajectory(ca.DM([1, 1]), ca.DM([4, 5]), 2, 0.4, 1.0)
    np.testing.assert_allclose(ref.full(), [[1.24, 1.48], [1.32, 1.64]], atol=1e-12)
    # A goal 0.5 m away: the direction is the unit (0, 1), so 0.4 m, then the remaining 0.1 m. Dividing by
    # max(||offset||, 1) instead of by ||offset|| would leave the direction (0, 0.5): 0.2, then 0.35.
    ref = costs.reference_trajectory(ca.DM([0, 0]), ca.DM([0, 0.5]), 2, 0.4, 1.0)
    np.testing.assert_allclose(ref.full(), [[0, 0], [0.4, 0.5]], atol=1e-12)
    # Standing on the goal: the reference stays there (no division by zero).
    ref = costs.reference_trajectory(ca.DM([2, 2]), ca.DM([2, 2]), 3, 0.4, 1.0)
    np.testing.assert_allclose(ref.full(), [[2, 2, 2], [2, 2, 2]])


def test_goal_cost_by_hand():
    # Errors (0, 0.1) and (0, -0.3): 0.01 + 0.09 = 0.1, divided by ||s_t - goal|| + delta = 1 + 0.001.
    positions = ca.DM([[0, 0], [0.5, 0.5]])
    reference = ca.DM([[0, 0], [0.4, 0.8]])
    cost = costs.goal_cost(positions, reference, ca.DM([0, 0]), ca.DM([0, 1]), 1e-3)
    assert value(cost) == pytest.approx(0.1 / 1.001)
    # Eq. 7 divides by the distance to the goal, not its square: error (0, 0.1) -> 0.01, the goal 2 m away
    # -> 0.01 / (2 + 0.001), not 0.01 / (4 + 0.001). (At 1 m, above, the two are the same.)
    cost = costs.goal_cost(ca.DM([0, 0.1]), ca.DM([0, 0]), ca.DM([0, 0]), ca.DM([0, 2]), 1e-3)
    assert value(cost) == pytest.approx(0.01 / 2.001, rel=1e-12)


def test_acceleration_and_jerk_costs_by_hand():
    accels = ca.DM([[1, 0], [2, -1]])  # a_0 = (1, 2), a_1 = (0, -1)
    assert value(costs.acceleration_cost(accels)) == pytest.approx(1 + 4 + 0 + 1)
    # With a_{-1} = (1, 0): differences (0, 2) and (-1, -3): 4 + 1 + 9
    assert value(costs.jerk_cost(accels, ca.DM([1, 0]))) == pytest.approx(14.0)


def test_human_collision_cost_by_hand():
    # Robot at (0, 0) moving at (1, 0), human at (1, 0): g = 0.64 + 0.5 * 1 - 1 = 0.14.
    # A second human far away (10 m) adds smax(0.64 + 0.5 - 100) ~ 0.
    positions, velocities = ca.DM([0, 0]), ca.DM([1, 0])
    humans = ca.DM([[1, 10], [0, 0]])
    cost = costs.human_collision_cost(positions, velocities, humans, 2, CFG)
    assert value(cost) == pytest.approx(math.log(math.exp(30 * 0.14) + 1) / 30)


def test_human_collision_cost_pairs_each_step_with_that_steps_humans():
    # H = 2, one human: at step 0 it is 1 m away (g = 0.64 - 1), at step 1 on top of the robot (g = 0.64).
    positions = ca.DM([[0, 0], [0, 0]])
    velocities = ca.DM.zeros(2, 2)
    humans = ca.DM([[1, 0], [0, 0]])  # column k * N_h + n
    cost = costs.human_collision_cost(positions, velocities, humans, 1, CFG)
    expected = math.log(math.exp(30 * -0.36) + 1) / 30 + math.log(math.exp(30 * 0.64) + 1) / 30
    assert value(cost) == pytest.approx(expected)


def test_human_collision_cost_takes_the_robots_position_at_each_step():
    # H = 2, velocities 0 (so rho ||v||^2 adds nothing); the robot is at (0, 0), then at (5, 0); one human
    # stands at (5, 0.5) at both steps. Step 1: 25.25 m^2 apart, g = 0.64 - 25.25 = -24.61, smax ~ 0;
    # step 2: 0.25 m^2 apart, g = 0.64 - 0.25 = 0.39, smax = 0.39 + log1p(exp(-30 * 0.39)) / 30.
    # Measured from the robot's first position at both steps the human would stay 5 m away: ~ 0.
    positions = ca.DM([[0.0, 5.0], [0.0, 0.0]])
    velocities = ca.DM.zeros(2, 2)
    humans = ca.DM([[5.0, 5.0], [0.5, 0.5]])
    got = value(costs.human_collision_cost(positions, velocities, humans, 1, CFG))
    expected = sum(max(g, 0.0) + math.log1p(math.exp(-30 * abs(g))) / 30 for g in (-24.61, 0.39))
    assert got == pytest.approx(expected, rel=1e-12)
    assert got > 0.39


def test_robot_collision_and_flocking_costs_by_hand():
    a, b = ca.DM([0, 0]), ca.DM([1, 0])
    # g = d_min^2 - d^2 = 0.64 - 1 = -0.36
    expected = math.log(math.exp(30 * -0.36) + 1) / 30
    assert value(costs.robot_collision_cost(a, b, CFG)) == pytest.approx(expected)
    # (sqrt(d^2 + delta) - d_ij)^2 with d = 2: (sqrt(4.001) - 1.2)^2
    far = ca.DM([0, 2])
    assert value(costs.flocking_cost(a, far, CFG)) == pytest.approx((math.sqrt(4.001) - 1.2) ** 2)
    # Eq. 15 sums over the horizon (no mean): 2 m apart at both of H = 2 steps counts twice.
    a2, far2 = ca.DM([[0, 0], [0, 0]]), ca.DM([[0, 0], [2, 2]])
    assert value(costs.flocking_cost(a2, far2, CFG)) == pytest.approx(2 * (math.sqrt(4.001) - 1.2) ** 2)


def test_individual_and_shared_costs_are_the_weighted_sums():
    rng = np.random.default_rng(1)
    state, accels = ca.DM(rng.normal(size=4)), ca.DM(rng.normal(size=(2, 3)))
    last, goal = ca.DM(rng.normal(size=2)), ca.DM([3.0, 4.0])
    humans = ca.DM(rng.normal(size=(2, 3 * 2)))
    track = costs.make_track(state, accels, last, goal, CFG.dt)
    reference = costs.reference_trajectory(state[0:2], goal, 3, CFG.dt, CFG.v_max)
    expected = (
        10.0 * value(costs.goal_cost(track.positions, reference, state[0:2], goal, CFG.delta))
        + 0.1 * value(costs.acceleration_cost(accels))
        + 0.1 * value(costs.jerk_cost(accels, last))
        + 1e7 * value(costs.human_collision_cost(track.positions, track.velocities, humans, 2, CFG))
    )
    assert value(costs.individual_cost(track, humans, 2, CFG)) == pytest.approx(expected)
    other = ca.DM(rng.normal(size=(2, 3)))
    shared = value(costs.shared_cost(track.positions, other, 7.0, CFG))
    expected = 1e7 * value(costs.robot_collision_cost(track.positions, other, CFG)) + 7.0 * value(
        costs.flocking_cost(track.positions, other, CFG)
    )
    assert shared == pytest.approx(expected)
    assert shared == pytest.approx(value(costs.shared_cost(other, track.positions, 7.0, CFG)))  # J_ij = J_ji
    # The random robots above are far apart (their collision term is ~1e-22, w_coll could be anything):
    # a second robot 0.5 m from this one at every step, inside d_min = 0.8 m.
    near = track.positions + ca.repmat(ca.DM([0.3, 0.4]), 1, 3)
    collision = value(costs.robot_collision_cost(track.positions, near, CFG))
    assert collision == pytest.approx(3 * (0.39 + math.log1p(math.exp(-30 * 0.39)) / 30))
    expected = 1e7 * collision + 7.0 * value(costs.flocking_cost(track.positions, near, CFG))
    assert value(costs.shared_cost(track.positions, near, 7.0, CFG)) == pytest.approx(expected)


def test_pair_index_enumerates_unordered_pairs_row_major():
    pairs = [(i, j) for i in range(4) for j in range(i + 1, 4)]
    assert [costs.pair_index(i, j, 4) for i, j in pairs] == list(range(6))
    assert costs.pair_index(3, 1, 4) == costs.pair_index(1, 3, 4)


def test_potential_counts_each_pair_once():
    # Two robots, no humans: F = J_1 + J_2 + J_12 and C_i = J_i + J_12, so C_1 + C_2 - F = J_12.
    rng = np.random.default_rng(2)
    tracks = [
        costs.make_track(
            ca.DM(rng.normal(size=4)),
            ca.DM(rng.normal(size=(2, 2))),
            ca.DM.zeros(2),
            ca.DM(rng.normal(size=2)),
            CFG.dt,
        )  # fmt: skip
        for _ in range(2)
    ]
    humans = ca.DM.zeros(2, 0)
    F = value(costs.potential(tracks, ca.DM([10.0]), humans, 0, CFG))
    c1 = value(costs.robot_cost(tracks[0], [tracks[1].positions], [10.0], humans, 0, CFG))
    c2 = value(costs.robot_cost(tracks[1], [tracks[0].positions], [10.0], humans, 0, CFG))
    j12 = value(costs.shared_cost(tracks[0].positions, tracks[1].positions, 10.0, CFG))
    assert c1 + c2 - F == pytest.approx(j12)


GOALS = MPCConfig(flock_distance="goals")
RANGE = MPCConfig(flock_range=2.5)  # seeds 5 and 9 below draw goals with pairs within it and beyond


@pytest.mark.parametrize(
    ("seed", "arrived", "cfg"),
    [
        (0, None, CFG),
        (1, None, CFG),
        (2, None, CFG),
        (3, [False, True, False], CFG),
        (4, None, GOALS),
        (5, None, RANGE),
        (9, None, RANGE),
    ],
)
def test_lemma_1_local_gradient_equals_potential_gradient(seed, arrived, cfg):
    """dC_i/du_i = dF/du_i (Lemma 1) for random states, plans, goals and predictions, 3 robots, 4 humans.
    With robot 1 arrived the pairs' flocking weights differ ((0,1) and (1,2) 0, (0,2) w_floc): each pair's
    own weight must reach both F and every C_i; with flock_distance "goals", each pair's own d_ij."""
    m, n, h = 3, 4, cfg.horizon
    rng = np.random.default_rng(seed)
    joint, local = JointNLP(cfg, m, n), LocalNLP(cfg, m, n)
    states = np.concatenate([rng.uniform(-1.5, 1.5, (m, 2)), rng.uniform(-1, 1, (m, 2))], axis=1)
    # Some robot-robot and robot-human distances inside the penalty zone, so every term contributes.
    data = StepData(
        states, rng.uniform(-2, 2, (m, 2)), rng.uniform(-4, 4, (m, 2)), np.ones(m, bool), arrived=arrived
    )
    humans = rng.uniform(-2, 2, (h, n, 2))
    accels = rng.uniform(-2, 2, (m, h, 2))
    u = ca.SX.sym("u", 2 * h * m)
    grad_F = ca.Function("dF", [u], [ca.gradient(joint.potential_fn(u, joint.params(data, humans)), u)])
    dF = grad_F(accels.ravel()).full().reshape(m, h, 2)
    positions = rollout_numpy(states, accels, cfg.dt)[0]
    for i in range(m):
        ui = ca.SX.sym("ui", 2 * h)
        params = local.params(i, data, positions, humans)
        grad_C = ca.Function("dC", [ui], [ca.gradient(local.cost_fn(ui, params), ui)])
        dC = grad_C(accels[i].ravel()).full().reshape(h, 2)
        scale = max(1.0, float(np.abs(dF[i]).max()))
        np.testing.assert_allclose(dC, dF[i], rtol=1e-9, atol=1e-9 * scale)
        assert np.abs(dF[i]).max() > 0


def test_flock_distances_are_the_goals_distances_above_d_flock_by_hand():
    """flock_distance "goals": d_ij = max(d_flock, ||g_i - g_j||), pairs (0,1), (0,2), (1,2); F then differs
    from the uniform d_flock by w_floc * sum_k [(n_k - d_ij)^2 - (n_k - 1.2)^2] on each pair."""
    states = np.array([[0.0, 0.0, 0, 0], [1.0, 0.0, 0, 0], [3.0, 0.0, 0, 0]])
    goals = np.array([[0.0, 5.0], [1.0, 5.0], [3.0, 5.0]])
    data = StepData(states, np.zeros((3, 2)), goals, np.ones(3, bool))
    np.testing.assert_allclose(data.flock_distances(1.2), [1.2, 3.0, 2.0])
    accels, humans = np.zeros((3, GOALS.horizon, 2)), np.zeros((GOALS.horizon, 0, 2))
    uniform = JointNLP(CFG, 3, 0).potential(accels, data, humans)
    by_goals = JointNLP(GOALS, 3, 0).potential(accels, data, humans)
    norms = np.sqrt(np.array([1.0, 9.0, 4.0]) + CFG.delta)  # the robots stand still: the same every step
    gap = ((norms - [1.2, 3.0, 2.0]) ** 2 - (norms - 1.2) ** 2).sum() * GOALS.horizon
    assert by_goals - uniform == pytest.approx(CFG.w_floc * gap, rel=1e-9)
    with pytest.raises(ValueError, match="flock_distance must be one of"):
        MPCConfig(flock_distance="shape")  # type: ignore[arg-type]


def test_flock_range_leaves_out_the_pairs_whose_goals_lie_beyond_it_by_hand():
    """Goals at x = 0, 1, 3: pairs (0,1), (0,2), (1,2) lie 1, 3 and 2 m apart. flock_range 2 keeps (0,1) and
    (1,2) at w_floc and gives (0,2) 0; F then lacks exactly that pair's Eq. 15 term; robot 1 arrived drops
    the other two as before; 0 (the default) keeps every pair, the paper's Eq. 15."""
    states = np.array([[0.0, 0.0, 0, 0], [1.0, 0.0, 0, 0], [3.0, 0.0, 0, 0]])
    goals = np.array([[0.0, 5.0], [1.0, 5.0], [3.0, 5.0]])
    data = StepData(states, np.zeros((3, 2)), goals, np.ones(3, bool))
    np.testing.assert_array_equal(data.floc_weights(10.0), [10.0, 10.0, 10.0])
    np.testing.assert_array_equal(data.floc_weights(10.0, 2.0), [10.0, 0.0, 10.0])
    arrived = dataclasses.replace(data, arrived=np.array([False, True, False]))
    np.testing.assert_array_equal(arrived.floc_weights(10.0, 2.0), [0.0, 0.0, 0.0])
    accels, humans = np.zeros((3, CFG.horizon, 2)), np.zeros((CFG.horizon, 0, 2))
    every = JointNLP(CFG, 3, 0).potential(accels, data, humans)
    near = JointNLP(CFG.replace(flock_range=2.0), 3, 0).potential(accels, data, humans)
    outer = (np.sqrt(9.0 + CFG.delta) - CFG.d_flock) ** 2 * CFG.horizon  # robots 0 and 2 stand 3 m apart
    assert every - near == pytest.approx(CFG.w_floc * outer, rel=1e-9)
    for bad in (-1.0, math.inf):
        with pytest.raises(ValueError, match="flock_range must be"):
            MPCConfig(flock_range=bad)
    with pytest.raises(ValueError, match="flock_range must be at most"):  # its bound guards the NLP
        JointNLP(CFG.replace(flock_range=1e4), 3, 0)


def test_human_margins_grow_the_distance_per_step_by_hand():
    """Eq. 11 with margins: (d_min + m_k)^2 + rho ||v||^2 - ||s - s_j||^2 inside smax, step k's own m_k."""
    cfg = MPCConfig(horizon=2, human_margins=(0.1, 0.3))
    positions = ca.DM([[0.0, 0.0], [0.0, 0.0]])  # the robot stands at the origin at both steps
    velocities = ca.DM.zeros(2, 2)
    humans = ca.DM([[1.0, 1.0], [0.0, 0.0]])  # one human 1 m away at both steps
    # Step 1: 0.9^2 - 1 = -0.19; step 2: 1.1^2 - 1 = 0.21.
    expected = sum(math.log1p(math.exp(cfg.mu * g)) / cfg.mu for g in (0.9**2 - 1.0, 1.1**2 - 1.0))
    got = value(costs.human_collision_cost(positions, velocities, humans, 1, cfg))
    assert got == pytest.approx(expected, rel=1e-12)
    # Without margins (the paper): 0.8^2 - 1 = -0.36 at both steps.
    paper = value(costs.human_collision_cost(positions, velocities, humans, 1, MPCConfig(horizon=2)))
    assert paper == pytest.approx(2 * math.log1p(math.exp(-0.36 * cfg.mu)) / cfg.mu, rel=1e-12)


def test_margins_leave_the_robot_robot_penalty_alone():
    cfg = MPCConfig(horizon=2, human_margins=(0.5, 0.5))
    a, b = ca.DM([[0.0, 0.0], [0.0, 0.0]]), ca.DM([[0.9, 0.9], [0.0, 0.0]])
    paper = MPCConfig(horizon=2)
    assert value(costs.robot_collision_cost(a, b, cfg)) == value(costs.robot_collision_cost(a, b, paper))


def test_human_collision_cost_reads_each_steps_own_velocity():
    """Eq. 11's ``rho ||v_{k+1}||^2`` pairs step k's position with the velocity at the same step."""
    # H = 2, the robot at the origin, one human 1 m away at both steps; the robot moves at 0.6 m/s at step 1
    # and stands at step 2: g = 0.64 + 0.5 * 0.36 - 1 = -0.18, then 0.64 - 1 = -0.36.
    positions = ca.DM.zeros(2, 2)
    velocities = ca.DM([[0.6, 0.0], [0.0, 0.0]])
    humans = ca.DM([[1.0, 1.0], [0.0, 0.0]])
    got = value(costs.human_collision_cost(positions, velocities, humans, 1, CFG))
    expected = sum(math.log1p(math.exp(30 * g)) / 30 for g in (-0.18, -0.36))
    assert got == pytest.approx(expected, rel=1e-12)


def test_goal_weight_keeps_the_goal_and_adds_the_slack_by_hand():
    """Eq. 7's weight ``1 / (||s_t - s_goal|| + delta + slack)`` uses the goal even when Eq. 8 heads for a
    detour target, and adds the track's ``goal_slack`` (on_goal="yield") to ``delta``."""
    # H = 2, the robot stands still at the origin with zero controls (no accel or jerk cost, no humans).
    # Target (2, 0): the reference is (0.4, 0), (0.8, 0), so the tracking error is 0.16 + 0.64 = 0.8.
    # The goal (0, 1) is 1 m away, the target 2 m: only the goal's 1 m may divide.
    cfg = MPCConfig(horizon=2)
    zero2 = ca.DM.zeros(2, 2)
    humans = ca.DM.zeros(2, 0)
    state, last, goal, target = ca.DM.zeros(4), ca.DM.zeros(2), ca.DM([0.0, 1.0]), ca.DM([2.0, 0.0])
    track = costs.make_track(state, zero2, last, goal, cfg.dt, target)
    assert value(costs.individual_cost(track, humans, 0, cfg)) == pytest.approx(10.0 * 0.8 / 1.001)
    slack = costs.make_track(state, zero2, last, goal, cfg.dt, target, goal_slack=0.5)
    assert value(costs.individual_cost(slack, humans, 0, cfg)) == pytest.approx(10.0 * 0.8 / 1.501)
    # goal_cost's own delta argument is the one used (not a constant 1e-3).
    positions, reference = ca.DM([[0.0], [0.0]]), ca.DM([[0.0], [0.5]])
    assert value(costs.goal_cost(positions, reference, ca.DM([0, 0]), ca.DM([0, 1]), 0.25)) == pytest.approx(
        0.25 / 1.25
    )


def test_collision_penalty_counts_robot_robot_and_robot_human_by_hand():
    """``collision_penalty`` = w_coll (every robot-human term + each robot pair once)."""
    # H = 1, robots standing at (0, 0) and (0.5, 0), one human at (0, 1):
    # the robot pair g = 0.64 - 0.25 = 0.39; robot 0 and the human 0.64 - 1 = -0.36; robot 1 and the human
    # 0.64 - 1.25 = -0.61.
    cfg = MPCConfig(horizon=1)
    tracks = [
        costs.make_track(ca.DM([x, 0, 0, 0]), ca.DM.zeros(2, 1), ca.DM.zeros(2), ca.DM([x, 5]), cfg.dt)
        for x in (0.0, 0.5)
    ]
    humans = ca.DM([[0.0], [1.0]])
    expected = 1e7 * sum(math.log1p(math.exp(30 * g)) / 30 for g in (0.39, -0.36, -0.61))
    assert value(costs.collision_penalty(tracks, humans, 1, cfg)) == pytest.approx(expected, rel=1e-12)


def test_each_weight_multiplies_its_own_term():
    """Eq. 13 with distinct weights, so that no term can borrow another's: w_goal 1, w_acce 2, w_jerk 3,
    w_coll 5, on one robot standing at the origin, H = 1, goal (0, 1), the reference 0.4 m towards it, control
    a_0 = (1, 0) after a_-1 = (0, 0), one human at (1, 0):
    goal: the position after one step is (0.08, 0) (0.4^2 / 2 * 1), error to (0, 0.4): 0.0064 + 0.16 = 0.1664,
          divided by 1 + 0.001; acce: 1; jerk: 1;
    coll: velocity (0.4, 0), g = 0.64 + 0.5 * 0.16 - 0.92^2 = -0.1264, smax(g) = log1p(exp(30 g)) / 30."""
    cfg = MPCConfig(horizon=1, w_goal=1.0, w_acce=2.0, w_jerk=3.0, w_coll=5.0)
    track = costs.make_track(ca.DM.zeros(4), ca.DM([1.0, 0.0]), ca.DM.zeros(2), ca.DM([0.0, 1.0]), cfg.dt)
    g = 0.64 + 0.5 * 0.16 - 0.92**2
    expected = 0.1664 / 1.001 + 2.0 + 3.0 + 5.0 * math.log1p(math.exp(30 * g)) / 30
    assert value(costs.individual_cost(track, ca.DM([1.0, 0.0]), 1, cfg)) == pytest.approx(
        expected, rel=1e-12
    )


def test_shared_cost_weights_the_robot_collision_by_hand():
    """Eq. 14's w_coll multiplies the robot-robot term: H = 1, robots 0.5 m apart, w_coll = 5.
    g = d_min^2 - d^2 = 0.64 - 0.25 = 0.39, smax(0.39) = 0.39 + log1p(exp(-30 * 0.39)) / 30."""
    cfg = MPCConfig(horizon=1, w_coll=5.0)
    a, b = ca.DM([0.0, 0.0]), ca.DM([0.5, 0.0])
    smax = 0.39 + math.log1p(math.exp(-30 * 0.39)) / 30
    assert value(costs.shared_cost(a, b, 0.0, cfg)) == pytest.approx(5.0 * smax, rel=1e-12)
    # with flocking weight 7: + 7 (sqrt(0.25 + 0.001) - 1.2)^2
    flock = (math.sqrt(0.251) - 1.2) ** 2
    assert value(costs.shared_cost(a, b, 7.0, cfg)) == pytest.approx(5.0 * smax + 7.0 * flock, rel=1e-12)


def test_individual_cost_takes_the_jerk_from_the_last_applied_action():
    """Eq. 10's a_{t-1} is the track's last action: H = 1, weights 1, the robot standing at the origin with
    a_0 = (0, 0) after a_-1 = (1, 2), goal (0, 1), no humans.
    goal: the robot stays at (0, 0), the reference is 0.4 m towards the goal: 0.16 / (1 + 0.001);
    acce: 0; jerk: (0 - 1)^2 + (0 - 2)^2 = 5 (0 if a_-1 were taken as 0)."""
    cfg = MPCConfig(horizon=1, w_goal=1.0, w_acce=1.0, w_jerk=1.0, w_coll=1.0)
    track = costs.make_track(ca.DM.zeros(4), ca.DM.zeros(2, 1), ca.DM([1.0, 2.0]), ca.DM([0.0, 1.0]), cfg.dt)
    got = value(costs.individual_cost(track, ca.DM.zeros(2, 0), 0, cfg))
    assert got == pytest.approx(0.16 / 1.001 + 5.0, rel=1e-12)


def test_individual_cost_references_at_the_configured_v_max():
    """Eq. 8's reference advances tau v_max per step with the config's v_max: v_max = 2 m/s, H = 1, weights
    1, the robot standing at the origin, no controls, goal (0, 5). The reference is 0.4 x 2 = 0.8 m towards
    the goal, the robot stays: 0.8^2 / (5 + 0.001) (0.4^2 / 5.001 at 1 m/s)."""
    cfg = MPCConfig(horizon=1, v_max=2.0, w_goal=1.0, w_acce=1.0, w_jerk=1.0, w_coll=1.0)
    track = costs.make_track(ca.DM.zeros(4), ca.DM.zeros(2, 1), ca.DM.zeros(2), ca.DM([0.0, 5.0]), cfg.dt)
    got = value(costs.individual_cost(track, ca.DM.zeros(2, 0), 0, cfg))
    assert got == pytest.approx(0.8**2 / 5.001, rel=1e-12)
