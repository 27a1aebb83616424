import numpy as np
import pytest

from predictors.constant_velocity import ConstantVelocity


def test_rollout_hand_computed():
    history = np.array([[[0.0, 0.0], [5.0, 5.0]], [[0.4, 0.0], [0.0, 0.0]]])  # (2 steps, 2 agents, 2)
    mask = np.array([[True, True], [True, False]])  # agent 1 seen once: it stays where it was
    out = ConstantVelocity().rollout(history, mask, None, np.array([0, 1]), horizon=3)
    np.testing.assert_allclose(out[:, 0], [[0.8, 0.0], [1.2, 0.0], [1.6, 0.0]])  # 1 m/s along x, 0.4 s steps
    np.testing.assert_allclose(out[:, 1], [[5.0, 5.0]] * 3)


@pytest.mark.parametrize("seed", range(5))
def test_rollout_and_casadi_function_agree(seed):
    rng = np.random.default_rng(seed)
    steps, n_agents, horizon = 8, 6, 7
    history = rng.normal(0.0, 3.0, (steps, n_agents, 2))
    mask = rng.random((steps, n_agents)) < 0.7
    mask[-1, :] |= rng.random(n_agents) < 0.5
    mask[:, 0] = True
    mask[rng.integers(steps), :] = True  # every agent observed at least once
    humans = np.array([0, 2, 3, 5])
    robots_future = rng.normal(0.0, 3.0, (horizon, n_agents - len(humans), 2))
    predictor = ConstantVelocity()
    numeric = predictor.rollout(history, mask, robots_future, humans)
    function = predictor.to_casadi(len(humans), n_agents - len(humans), horizon)
    symbolic = np.asarray(
        function(predictor.encode(history, mask, humans), robots_future.reshape(-1))
    ).ravel()
    np.testing.assert_allclose(symbolic, numeric.reshape(-1), rtol=0, atol=1e-9)


def test_the_velocity_is_the_last_consecutive_difference():
    # Agent 0 walks (0, 0) -> (0.4, 0) -> (0.4, 0.8): the last difference, (0, 0.8) / 0.4 = (0, 2) m/s, from
    # the last position (0.4, 0.8). Agent 1 is seen at steps 0 and 2 but not 1: no two consecutive steps at
    # the end, so it stands at its last position (3, 3) rather than moving at (3 - 1) / 0.8 m/s.
    history = np.array([[[0.0, 0.0], [1.0, 1.0]], [[0.4, 0.0], [0.0, 0.0]], [[0.4, 0.8], [3.0, 3.0]]])
    mask = np.array([[True, True], [True, False], [True, True]])
    out = ConstantVelocity().rollout(history, mask, None, np.array([0, 1]), horizon=2)
    np.testing.assert_allclose(out[:, 0], [[0.4, 1.6], [0.4, 2.4]])
    np.testing.assert_allclose(out[:, 1], [[3.0, 3.0], [3.0, 3.0]])


def test_a_human_missing_at_the_last_steps_is_extrapolated_to_the_current_step():
    """Walking +x at 1 m/s, last seen at step 5 of 9: at t + 1 it is at 0.4 * 9 = 3.6 m, not 2.4 (from where
    it was last seen, three steps late); the learned predictors impute it to the current step the same way.
    The CasADi function, from encode, agrees."""
    history = np.zeros((9, 2, 2))
    history[:, 0, 0] = 0.4 * np.arange(9)
    history[:, 1] = [5.0, 5.0]
    mask = np.ones((9, 2), dtype=bool)
    mask[6:, 0] = False
    predictor = ConstantVelocity()
    out = predictor.rollout(history, mask, None, np.array([0, 1]), horizon=3)
    np.testing.assert_allclose(out[:, 0], [[3.6, 0.0], [4.0, 0.0], [4.4, 0.0]], atol=1e-12)
    np.testing.assert_array_equal(out[:, 1], [[5.0, 5.0]] * 3)
    function = predictor.to_casadi(2, 0, 3)
    symbolic = np.asarray(function(predictor.encode(history, mask, np.array([0, 1])), np.zeros(0))).ravel()
    np.testing.assert_allclose(symbolic, out.reshape(-1), rtol=0, atol=1e-12)


def test_an_agent_never_observed_cannot_be_predicted():
    history = np.zeros((2, 2, 2))
    mask = np.array([[True, False], [True, False]])
    with pytest.raises(ValueError, match="agent 1 is never observed"):
        ConstantVelocity().rollout(history, mask, None, np.array([0, 1]), horizon=2)
    with pytest.raises(ValueError, match="obs_len must be >= 1"):
        ConstantVelocity(obs_len=0)
