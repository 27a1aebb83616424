"""The coupled NLP (beyond the paper): the predictor's CasADi twin inside the joint NLP."""

import numpy as np
import pytest

from mpc.cmpc import CMPC
from mpc.config import MPCConfig
from mpc.coupled import CoupledCMPC
from mpc.fallback import PlanMemory
from mpc.nlp import StepData
from predictors.base import DT
from predictors.constant_velocity import ConstantVelocity
from tests.mpc.reactive import ReactivePredictor


def scene():
    """Three robots heading north, two humans walking south into them; history robots first."""
    states = np.array([[-1.2, -3.0, 0, 0.5], [0.0, -3.0, 0, 0.5], [1.2, -3.0, 0, 0.5]], dtype=float)
    data = StepData(states, np.zeros((3, 2)), states[:, :2] + [0.0, 6.0], np.ones(3, dtype=bool))
    now = np.concatenate([states[:, :2], [[-0.5, -0.5], [0.7, 0.0]]])
    previous = now - np.concatenate([states[:, 2:], [[0.0, -1.0], [0.0, -1.0]]]) * DT
    history = np.stack([previous, now])
    return data, history, np.ones(history.shape[:2], dtype=bool), np.array([3, 4])


def coupled(cfg, predictor):
    function = predictor.to_casadi(2, 3, cfg.horizon)
    return CoupledCMPC(cfg, 3, 2, function, predictor.context_size(2, 3))


@pytest.mark.parametrize("mode", ["exact", "first_order"])
def test_constant_velocity_coupled_equals_fixed_predictions(mode):
    cfg = MPCConfig(coupled_mode=mode, multi_start=False, solver_tol=1e-9)
    data, history, mask, humans = scene()
    predictor = ConstantVelocity()
    start = PlanMemory(cfg).start(data)
    result = coupled(cfg, predictor).solve(data, predictor.encode(history, mask, humans), start)
    reference = CMPC(cfg, 3, 2).solve(data, lambda rf: predictor.rollout(history, mask, rf, humans), start)
    assert result.solved and result.status == "ok"
    np.testing.assert_allclose(result.prediction, reference.prediction, atol=1e-12)
    assert result.potential == pytest.approx(reference.potential, rel=1e-6)
    np.testing.assert_allclose(result.accels, reference.accels, atol=1e-4)


def test_first_order_model_of_a_linear_predictor_is_exact():
    data, history, mask, humans = scene()
    predictor = ReactivePredictor(gain=0.3)
    context = predictor.encode(history, mask, humans)
    out = {}
    for mode in ("exact", "first_order"):
        cfg = MPCConfig(coupled_mode=mode, multi_start=False, solver_tol=1e-9)
        out[mode] = coupled(cfg, predictor).solve(data, context, PlanMemory(cfg).start(data))
        assert out[mode].solved
    assert out["first_order"].potential == pytest.approx(out["exact"].potential, rel=1e-6)
    np.testing.assert_allclose(out["first_order"].accels, out["exact"].accels, atol=1e-4)
    # The prediction reported is the predictor's own at the returned plan.
    plan = out["exact"].positions.transpose(1, 0, 2)
    np.testing.assert_allclose(
        out["exact"].prediction, predictor.rollout(history, mask, plan, humans), atol=1e-12
    )


def test_accounting_for_the_reaction_does_not_lose_to_ibr():
    """Minimising F(u, f(u)) directly is at least as good, on F(u, f(u)), as IBR's equilibrium."""
    data, history, mask, humans = scene()
    predictor = ReactivePredictor(gain=0.3)
    cfg = MPCConfig(coupled_mode="exact", multi_start=False)
    solver = coupled(cfg, predictor)
    start = PlanMemory(cfg).start(data)
    coupled_result = solver.solve(data, predictor.encode(history, mask, humans), start)
    ibr = CMPC(cfg, 3, 2).solve(data, lambda rf: predictor.rollout(history, mask, rf, humans), start)
    true_prediction = predictor.rollout(history, mask, ibr.positions.transpose(1, 0, 2), humans)
    ibr_true = CMPC(cfg, 3, 2).nlp.potential(ibr.accels, data, true_prediction)
    assert coupled_result.potential <= ibr_true + 1e-6


def test_non_finite_context_falls_back():
    data, history, mask, humans = scene()
    predictor = ConstantVelocity()
    cfg = MPCConfig()
    context = predictor.encode(history, mask, humans)
    context[0] = np.nan
    result = coupled(cfg, predictor).solve(data, context, PlanMemory(cfg).start(data))
    assert not result.solved and result.status == "nan_prediction"


def test_auto_mode_expands_small_predictors_and_linearises_big_ones(monkeypatch):
    import mpc.coupled

    cfg = MPCConfig()
    assert cfg.coupled_mode == "auto"
    assert coupled(cfg, ConstantVelocity()).mode == "exact"
    monkeypatch.setattr(mpc.coupled, "EXPAND_MAX_NODES", 0)  # every predictor counts as a network now
    solver = coupled(cfg, ConstantVelocity())
    assert solver.mode == "first_order"
    data, history, mask, humans = scene()
    result = solver.solve(data, ConstantVelocity().encode(history, mask, humans), PlanMemory(cfg).start(data))
    assert result.solved and result.iterations == 2 and result.solves == 1  # J = 0: same model twice


def test_exact_mode_keeps_a_big_predictor_as_a_call_node_with_lbfgs(monkeypatch):
    import casadi as ca

    import mpc.coupled

    monkeypatch.setattr(mpc.coupled, "EXPAND_MAX_NODES", 0)
    # L-BFGS on the 1e7-weighted penalties needs far more iterations than the exact Hessian.
    cfg = MPCConfig(coupled_mode="exact", multi_start=False, solver_max_iter=3000, time_limit_s=10.0)
    predictor = ConstantVelocity()
    solver = coupled(cfg, predictor)
    assert solver.model.symbolic is ca.MX
    assert solver.model.ipopt_options == {"ipopt.hessian_approximation": "limited-memory"}
    data, history, mask, humans = scene()
    start = PlanMemory(cfg).start(data)
    result = solver.solve(data, predictor.encode(history, mask, humans), start)
    reference = CMPC(cfg, 3, 2).solve(data, lambda rf: predictor.rollout(history, mask, rf, humans), start)
    assert result.solved
    assert result.potential == pytest.approx(reference.potential, rel=1e-4)
