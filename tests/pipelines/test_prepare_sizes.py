"""MPCController.prepare: the sizes a real robot's loop will meet, built before it and none inside it."""

import pytest

import mpc.solvers
import predictors.learned_casadi
from crowdsim.env import CrowdEnv
from mpc.config import MPCConfig
from mpc.nlp import JointNLP, LocalNLP
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller


def _no_build(*args, **kwargs):
    raise AssertionError("built inside the loop")


@pytest.mark.parametrize("name", ["cmpc", "dmpc"])
def test_a_prepared_size_builds_nothing_in_the_loop_and_another_size_does(name, monkeypatch):
    controller = make_controller(ControllerSpec(name, predictor="social_lstm_eth"))
    seconds = controller.prepare(3, [4, 2])
    assert list(seconds) == [(3, 4), (3, 2)] and all(s > 0 for s in seconds.values())
    # the NLPs' solvers, the predictor's twin and its encoder are all built through these two
    monkeypatch.setattr(mpc.solvers, "build_nlpsol", _no_build)
    monkeypatch.setattr(predictors.learned_casadi, "export_function", _no_build)
    env = CrowdEnv()
    for n_humans in (2, 4):  # people come and go
        obs = env.reset(0, "circle", n_humans, 3)
        controller.reset(obs)
        for _ in range(2):
            out = controller.act(obs)
            assert out.fallback is None
            obs, _, _ = env.step(out.accelerations)
    with pytest.raises(AssertionError, match="built inside the loop"):
        controller.reset(env.reset(0, "circle", 3, 3))  # not prepared: built here
    assert controller.prepare(3, [2])[(3, 2)] < 0.05  # built already
    controller.close()


@pytest.mark.parametrize("nlp", [lambda cfg: JointNLP(cfg, 2, 1), lambda cfg: LocalNLP(cfg, 2, 1)])
def test_build_all_builds_the_warm_ipopt_a_failed_fatrop_solve_would_build(nlp, monkeypatch):
    built = nlp(MPCConfig())
    built.build_all()
    monkeypatch.setattr(mpc.solvers, "build_nlpsol", _no_build)
    solvers = built._solvers if isinstance(built, LocalNLP) else [built._solver()]
    for solver in solvers:
        solver._ipopt(warm=True)  # what Solver.solve calls after a failed warm-started Fatrop solve


@pytest.mark.parametrize(
    "n_robots, n_humans, match",
    [
        (3, 7, "n_humans must be the numbers of humans to prepare for .* got the int 7"),
        (0, [1], "n_robots must be an int >= 1, got 0"),
        (True, [1], "n_robots must be an int >= 1, got True"),
        (3, [2, -1], r"each number of humans must be an int in 0\.\.50, got -1 in n_humans"),
        (3, [100_000], "got 100000 in n_humans"),  # gigabytes and minutes, without a word
        (3, [1.5], "got 1.5 in n_humans"),
        (3, "7", "got '7' in n_humans"),
        (3, None, "n_humans must be the numbers of humans to prepare for .* got None"),
    ],
)
def test_prepare_refuses_sizes_that_are_not_counts(n_robots, n_humans, match):
    controller = make_controller(ControllerSpec("cmpc"))
    with pytest.raises(PipelineError, match=match):
        controller.prepare(n_robots, n_humans)
    assert controller._solvers == {}  # refused before anything was built
