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
