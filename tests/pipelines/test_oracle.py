"""The ORCA oracle predicts exactly what the simulator does when the robots follow the plan."""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
from predictors.errors import PredictorError
from predictors.oracle import OrcaOracle
from predictors.registry import load_predictor


def _plan(obs, accelerations: np.ndarray) -> np.ndarray:
    """Robot positions (H, M, 2) of the double integrator (Eq. 2) under accelerations (H, M, 2)."""
    p, v, out = obs.robot_positions.copy(), obs.robot_velocities.copy(), []
    for a in accelerations:
        p = p + obs.dt * v + 0.5 * obs.dt**2 * a
        v = v + obs.dt * a
        out.append(p)
    return np.stack(out)


@pytest.mark.parametrize("scenario", ["circle", "perpendicular"])
def test_oracle_equals_the_simulator_over_the_horizon(scenario):
    env = CrowdEnv()
    obs = env.reset(seed=3, scenario=scenario, n_humans=7, n_robots=3)
    for _ in range(3):  # leave the standing start: humans and robots moving
        obs, _, _ = env.step(np.tile([0.0, 0.5], (3, 1)))
    # Small accelerations stay inside the bounds, so the simulator applies them unclipped.
    accelerations = np.stack([np.tile([0.3 * (-1) ** k, 0.2], (3, 1)) for k in range(4)])
    oracle = OrcaOracle()
    oracle.observe(obs, EnvConfig())
    m, n = obs.n_robots, obs.n_humans
    humans = np.arange(m, m + n)
    mask = np.ones(obs.history.shape[:2], dtype=bool)
    predicted = oracle.rollout(obs.history, mask, _plan(obs, accelerations), humans)
    actual = []
    for a in accelerations:
        obs, done, info = env.step(a)
        assert not info["clipped"].any()
        actual.append(obs.human_positions)
    np.testing.assert_allclose(predicted, np.stack(actual), rtol=0, atol=1e-9)


def test_oracle_returns_the_humans_asked_for_in_their_order():
    env = CrowdEnv()
    obs = env.reset(seed=0, scenario="circle", n_humans=5, n_robots=3)
    oracle = OrcaOracle()
    oracle.observe(obs, EnvConfig())
    mask = np.ones(obs.history.shape[:2], dtype=bool)
    everyone = oracle.rollout(obs.history, mask, None, np.arange(3, 8), horizon=4)
    two = oracle.rollout(obs.history, mask, None, np.array([6, 4]), horizon=4)
    np.testing.assert_array_equal(two, everyone[:, [3, 1]])


def test_oracle_refuses_a_history_it_was_not_told_about():
    env = CrowdEnv()
    obs = env.reset(seed=0, scenario="circle", n_humans=5, n_robots=3)
    oracle = OrcaOracle()
    mask = np.ones(obs.history.shape[:2], dtype=bool)
    with pytest.raises(PredictorError, match="observe"):
        oracle.rollout(obs.history, mask, None, np.arange(3, 8), horizon=2)
    oracle.observe(obs, EnvConfig())
    later, _, _ = env.step(np.zeros((3, 2)))
    with pytest.raises(PredictorError, match="observe"):
        oracle.rollout(later.history, mask, None, np.arange(3, 8), horizon=2)
    with pytest.raises(PredictorError, match="CasADi"):
        oracle.to_casadi(5, 3, 4)


def test_the_mpc_hands_the_oracle_each_observation_and_the_simulators_settings():
    env_config = EnvConfig(robots_visible=False)
    controller = make_controller(ControllerSpec("cmpc", "orca_oracle"), env_config)
    assert isinstance(controller.model, OrcaOracle) and controller.predictor == "orca_oracle"
    env = CrowdEnv(env_config)
    obs = env.reset(seed=0, scenario="circle", n_humans=5, n_robots=3)
    controller.reset(obs)
    assert controller.model._obs is obs and controller.model.env_config is env_config
    out = controller.act(obs)
    later, _, _ = env.step(out.accelerations)
    controller.act(later)
    assert controller.model._obs is later


def test_the_oracle_is_a_registered_predictor_that_refuses_the_coupled_nlp():
    assert isinstance(load_predictor("orca_oracle"), OrcaOracle)
    with pytest.raises(PipelineError, match="coupling 'ibr'"):
        make_controller(ControllerSpec("cmpc", "orca_oracle", coupling="nlp"))


def test_the_oracle_has_no_twin_and_the_loop_says_nothing_of_it():
    """NoCasadiTwin is the oracle's by design: the IBR loop predicts with it numerically, silently."""
    import warnings

    from predictors.errors import NoCasadiTwin

    with pytest.raises(NoCasadiTwin, match="no CasADi twin"):
        OrcaOracle().to_casadi(2, 3, 4)
    controller = make_controller(ControllerSpec("cmpc", predictor="orca_oracle"))
    obs = CrowdEnv().reset(0, "circle", 2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        controller.reset(obs)
        controller.act(obs)


def test_a_twin_that_fails_its_check_is_named_and_torch_predicts(monkeypatch):
    """A twin that exists but disagrees with torch (or uses an operation the exporter lacks) is not the
    oracle's case: the loop still runs, in torch, and warns instead of passing it by."""
    from predictors.export import ExportError, parity

    def failing(predictor, *size):
        raise ExportError("the exported prediction differs from torch by 1.00e-01", predictor.name)

    monkeypatch.setattr(parity, "require_parity", failing)
    controller = make_controller(ControllerSpec("cmpc", predictor="social_lstm_eth"))
    obs = CrowdEnv().reset(0, "circle", 2)
    with pytest.warns(RuntimeWarning, match="'social_lstm_eth': no CasADi twin .*differs from torch"):
        controller.reset(obs)
    out = controller.act(obs)
    assert out.status == "ok" and np.isfinite(out.accelerations).all()
    # the coupled NLP cannot run it in torch: refused as the controller is built, not in the first step
    with pytest.raises(PipelineError) as refused:
        make_controller(ControllerSpec("cmpc", predictor="social_lstm_eth", coupling="nlp"))
    assert str(refused.value) == (
        "coupling 'nlp' puts the predictor inside the joint NLP, and 'social_lstm_eth' has no CasADi twin "
        "(cannot export: the exported prediction differs from torch by 1.00e-01 (in module "
        "'social_lstm_eth')): use coupling 'ibr', which runs it in torch"
    )


def test_the_commands_show_a_missing_twin_as_a_note_and_other_warnings_as_python_does(capsys):
    """The CLI printed the warning with its file, line number and source line, unlike its other notes."""
    import warnings

    from pipelines.errors import NoTwinWarning, warnings_as_notes

    others = []
    with warnings.catch_warnings():  # it restores the showwarning in force
        warnings.simplefilter("always")
        warnings.showwarning = lambda message, category, *rest: others.append((str(message), category))
        warnings_as_notes()
        warnings_as_notes()  # once only: a second call does not wrap the first
        warnings.warn("predictor 'p': no CasADi twin (x)", NoTwinWarning, stacklevel=1)
        warnings.warn("something else", UserWarning, stacklevel=1)
    assert capsys.readouterr().err == "note: predictor 'p': no CasADi twin (x)\n"
    assert others == [("something else", UserWarning)]

    class ClosedPipe:
        def write(self, text: str) -> int:
            raise BrokenPipeError(32, "Broken pipe")

    with warnings.catch_warnings():  # a note lost to a closed pipe raises nothing, as Python's own warnings
        warnings.simplefilter("always")
        warnings_as_notes()
        warnings.showwarning("lost", NoTwinWarning, "f.py", 1, ClosedPipe())  # type: ignore[arg-type]


@pytest.mark.parametrize("controller", ["cmpc", "dmpc"])
def test_reset_builds_everything_the_first_step_needs(controller, monkeypatch):
    """The first timed step must not build: IPOPT's cold solver (every first step explores with it) and the
    exported encoder (its first call builds it) were built there, 2-5x the cost of a later first step."""
    controller_ = make_controller(ControllerSpec(controller, predictor="social_lstm_eth"))
    obs = CrowdEnv().reset(0, "circle", 3)
    controller_.reset(obs)

    def no_build(*args, **kwargs):
        raise AssertionError("built inside the first step")

    monkeypatch.setattr("mpc.solvers.build_nlpsol", no_build)
    monkeypatch.setattr("predictors.learned_casadi.export_function", no_build)
    out = controller_.act(obs)
    assert out.status == "ok" and out.fallback is None
