"""``coupling="none"``: predict, then plan. The predictor sees the humans' past alone, so its predictions do
not answer the robots' plans (the ablation of the paper's coupling), and the IBR loop stops at its second
solve."""

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from pipelines.experiments.methods import ORACLE_PREDICTOR, SWAP_PREDICTORS
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.mpc_setup import predictor_history
from tests.cli_calls import one_line, run_cli


def walking_crowd(steps=6, seed=1):
    """An observation of 7 humans walking across the robots' circle, the robots standing at their starts."""
    env = CrowdEnv()
    obs = env.reset(seed, "circle", 7)
    for _ in range(steps):
        obs, _, _ = env.step(np.zeros((3, 2)))
    return obs


def act(spec, obs):
    controller = make_controller(spec)
    controller.reset(obs)
    return controller, controller.act(obs)


@pytest.mark.parametrize("controller", ["cmpc", "dmpc"])
def test_the_prediction_is_the_humans_past_alone_whatever_the_robots_plan(controller):
    obs = walking_crowd()
    blind, out = act(ControllerSpec(controller, "social_lstm_eth", coupling="none"), obs)
    history, mask = predictor_history(obs, blind.model.obs_len)
    horizon = out.prediction.shape[0]
    alone = blind.model.rollout(history[:, 3:], mask[:, 3:], np.zeros((horizon, 0, 2)), np.arange(7))
    np.testing.assert_allclose(out.prediction, alone, atol=1e-6)  # the twin, within its contract
    assert out.status == "ok"
    if controller == "cmpc":
        assert out.iterations == 2  # the second prediction is the first: converged, not solved again
    # the paper's coupling predicts these humans answering the robots, who stand among them
    _, coupled = act(ControllerSpec(controller, "social_lstm_eth"), obs)
    assert np.abs(coupled.prediction - alone).max() > 1e-3


def test_an_episode_predicting_then_planning_runs_and_says_so(capsys):
    argv = ["simulate", "--controller", "cmpc", "--coupling", "none", "--humans", "3", "--episodes", "1"]
    code, out, _ = run_cli(capsys, *argv, "--no-progress", "--no-flocking")
    assert code == 0
    assert out.startswith("controller cmpc | predictor constant_velocity | coupling none | no flocking | ")


def test_the_orca_oracle_cannot_predict_blind_to_the_robots(capsys):
    argv = ["simulate", "--controller", "dmpc", "--predictor", "orca_oracle", "--coupling", "none"]
    code, _, err = run_cli(capsys, *argv)
    assert code == 2 and one_line(err).endswith(
        "the orca_oracle predictor predicts the simulator's humans, who see the robots: coupling 'none' "
        "takes a predictor that predicts from the past alone"
    )


@pytest.mark.parametrize("controller", ["cmpc", "dmpc"])
def test_the_mpc_loads_its_predictor_once(controller, monkeypatch):
    """DMPC's early refusal of a coupled NLP loaded the predictor for coupling "none" too, then the
    controller loaded it again (a checkpoint read twice per build), and refused the oracle only then."""
    from pipelines.loop import mpc
    from pipelines.loop.mpc import MPCController
    from predictors import registry

    loads, load = [], registry.load_predictor

    def counted(name):
        loads.append(name)
        return load(name)

    monkeypatch.setattr(mpc, "load_predictor", counted)
    monkeypatch.setattr(registry, "load_predictor", counted)  # check_coupling imports it from there
    MPCController(ControllerSpec(controller, "social_lstm_eth", coupling="none"), controller == "dmpc")
    assert loads == ["social_lstm_eth"]


def test_predicting_then_planning_compiles_its_nlps_as_the_paper_s_coupling_does():
    import dataclasses

    from pipelines.commands.sweep_jit import jit_pays
    from pipelines.experiments.cells import EXPERIMENTS

    cells = EXPERIMENTS["table2"].cells()
    blind = [dataclasses.replace(c, spec=dataclasses.replace(c.spec, coupling="none")) for c in cells]
    nlp = [dataclasses.replace(c, spec=dataclasses.replace(c.spec, coupling="nlp")) for c in cells]
    # the same NLPs as the paper's (predictions are parameters), so the same episodes repay them
    assert [jit_pays(blind, n) for n in (35, 36)] == [jit_pays(cells, n) for n in (35, 36)] == [False, True]
    assert not jit_pays(nlp, 1000)  # the coupled NLP is never compiled


@pytest.mark.parametrize(
    "predictor", [p for p in SWAP_PREDICTORS if p not in ("constant_velocity", ORACLE_PREDICTOR)]
)
def test_every_shipped_net_predicts_blind_through_its_twin_and_nobody_needs_none(predictor):
    """Among a replayed crowd the MPC is built for every crowd size from 0: predicting blind, 0 humans is
    nobody at all, which no net exports (a cell of the predictors sweep failed on it) and none is needed."""
    import warnings

    controller = make_controller(ControllerSpec("cmpc", predictor, coupling="none"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "no CasADi twin ... predicts with torch instead" would be one
        controller.prepare(3, range(4))
    assert all(controller._twin(n, 0) is not None for n in (1, 2, 3))
    obs = walking_crowd()
    predict = controller._predict_fn(*predictor_history(obs, controller.model.obs_len), np.arange(3, 3))
    assert predict(np.zeros((4, 3, 2))).shape == (4, 0, 2)
