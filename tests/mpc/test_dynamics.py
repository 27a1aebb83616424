"""Eq. 2 against hand-integrated steps, and the numpy helpers against the CasADi rollout."""

import casadi as ca
import numpy as np

from mpc.dynamics import braking, clip_to_bounds, rollout, rollout_numpy, step


def test_one_step_by_hand():
    # s' = s + tau v + tau^2 a / 2 = 0.4 * 1 + 0.08 * 2 = 0.56; v' = 1 + 0.4 * 2 = 1.8
    out = step(ca.DM([0, 0, 1, 0]), ca.DM([2, 0]), 0.4)
    np.testing.assert_allclose(out.full().ravel(), [0.56, 0.0, 1.8, 0.0])


def test_two_steps_by_hand():
    # Step 2 from x = (0.56, 1.8), y = (0, 0) with a = (-1, 1):
    # x: 0.56 + 0.4 * 1.8 - 0.08 = 1.2, vx = 1.8 - 0.4 = 1.4; y: 0.08, vy = 0.4
    accels = ca.DM([[2, -1], [0, 1]])  # (2, H): column k is a_k
    positions, velocities = rollout(ca.DM([0, 0, 1, 0]), accels, 0.4)
    np.testing.assert_allclose(positions.full(), [[0.56, 1.2], [0.0, 0.08]])
    np.testing.assert_allclose(velocities.full(), [[1.8, 1.4], [0.0, 0.4]])


def test_numpy_rollout_matches_casadi_rollout():
    rng = np.random.default_rng(0)
    states = rng.normal(size=(3, 4))
    accels = rng.normal(size=(3, 5, 2))
    positions, velocities = rollout_numpy(states, accels, 0.4)
    for i in range(3):
        p, v = rollout(ca.DM(states[i]), ca.DM(accels[i].T), 0.4)
        np.testing.assert_allclose(positions[i], p.full().T, atol=1e-12)
        np.testing.assert_allclose(velocities[i], v.full().T, atol=1e-12)


def test_braking_by_hand():
    # v = (0.5, -1.2): a_0 = clip(-v / 0.4, +-2) = (-1.25, 2.0) -> v = (0, -0.4); a_1 = (0, 1.0) -> v = 0
    out = braking(np.array([[0.0, 0.0, 0.5, -1.2]]), 3, 0.4, 2.0)
    np.testing.assert_allclose(out[0], [[-1.25, 2.0], [0.0, 1.0], [0.0, 0.0]])


def test_clip_to_bounds_keeps_velocity_and_acceleration_within_eq6():
    # Step 0: v_x = 0.9 allows a_x <= (1 - 0.9) / 0.4 = 0.25; a_y = 3 is clipped to a_max = 2.
    # Step 1: v = (1.0, 0.8) allows a_x <= 0 and a_y <= (1 - 0.8) / 0.4 = 0.5.
    out = clip_to_bounds(np.array([[0, 0, 0.9, 0.0]]), np.array([[[1.0, 3.0], [1.0, 1.0]]]), 0.4, 1.0, 2.0)
    np.testing.assert_allclose(out[0], [[0.25, 2.0], [0.0, 0.5]])


def test_braking_stays_within_a_max_over_several_steps():
    # v_x = 2 with a_max = 2, tau = 0.4: each step removes at most 0.8 m/s, so -2, -2 (v = 1.2, then 0.4),
    # then the remaining -0.4 / 0.4 = -1, then rest.
    out = braking(np.array([[0.0, 0.0, 2.0, 0.0]]), 4, 0.4, 2.0)
    np.testing.assert_allclose(out[0, :, 0], [-2.0, -2.0, -1.0, 0.0])


def test_clip_to_bounds_mirrors_the_bounds_for_negative_velocities():
    # v_x = -0.9 allows a_x >= (-1 + 0.9) / 0.4 = -0.25; a_y = -3 is clipped to -a_max = -2.
    # Step 1: v = (-1.0, -0.8) allows a_x >= 0 and a_y >= (-1 + 0.8) / 0.4 = -0.5.
    out = clip_to_bounds(
        np.array([[0, 0, -0.9, 0.0]]), np.array([[[-1.0, -3.0], [-1.0, -1.0]]]), 0.4, 1.0, 2.0
    )
    np.testing.assert_allclose(out[0], [[-0.25, -2.0], [0.0, -0.5]])


def test_clip_to_bounds_brings_an_excess_velocity_back_at_a_max():
    # v_x = 2 > v_max = 1: reaching v_max in one step would need (1 - 2) / 0.4 = -2.5, beyond a_max = 2, so
    # a_x = -2 (v_x = 1.2), then (1 - 1.2) / 0.4 = -0.5 reaches v_max; the wanted 0 is never allowed.
    out = clip_to_bounds(np.array([[0, 0, 2.0, 0.0]]), np.zeros((1, 3, 2)), 0.4, 1.0, 2.0)
    np.testing.assert_allclose(out[0, :, 0], [-2.0, -0.5, 0.0])
    np.testing.assert_allclose(out[0, :, 1], 0.0)
