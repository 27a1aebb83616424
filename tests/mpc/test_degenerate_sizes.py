"""One robot and no humans: no robot pair and no human, so the collision penalty is a sum over nothing.

CasADi makes such a sum a structurally empty 1x1, which mpc/fastcall.py refused to bind ("penalty: output
penalty is not dense"): the NLPs could not even be built.
"""

import numpy as np
import pytest

from mpc import costs
from mpc.cmpc import CMPC
from mpc.config import MPCConfig
from mpc.dmpc import DMPC
from mpc.fallback import PlanMemory
from mpc.nlp import JointNLP, LocalNLP, StepData
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode


@pytest.mark.parametrize("nlp", [JointNLP, LocalNLP])
def test_penalty_alone_without_humans_is_a_dense_zero(nlp):
    problem = nlp(MPCConfig(), n_robots=1, n_humans=0)
    assert problem.penalty_fn.sparsity_out(0).is_dense()
    assert _penalty_anywhere(problem.penalty_fn) == 0.0  # nothing to collide with, whatever the plan


def _penalty_anywhere(penalty_fn) -> float:
    """The penalty at a random plan and parameters (no human and no robot pair: no value should matter)."""
    rng = np.random.default_rng(0)
    return float(penalty_fn(*(rng.normal(size=penalty_fn.size_in(i)) for i in range(2))))


def test_dense_leaves_a_dense_expression_untouched():
    """The normal case keeps its expression graph (and so every number) as it was."""
    import casadi as ca

    x = ca.SX.sym("x", 2)
    expr = ca.sumsqr(x)
    assert costs.dense(expr) is expr
    empty = ca.sum2(ca.SX(1, 0))
    assert not empty.sparsity().is_dense() and costs.dense(empty).sparsity().is_dense()


@pytest.mark.parametrize(
    "spec",
    [ControllerSpec("cmpc"), ControllerSpec("dmpc"), ControllerSpec("cmpc", coupling="nlp")],
    ids=["cmpc", "dmpc", "cmpc-nlp"],
)
@pytest.mark.parametrize("scenario", ["circle", "perpendicular"])
def test_one_robot_without_humans_reaches_its_goal(spec, scenario):
    result = run_episode(make_controller(spec), seed=0, scenario=scenario, n_humans=0, n_robots=1)
    assert result.metrics.success and not result.metrics.timeout
    assert all(f is None for f in result.fallbacks)
    np.testing.assert_allclose(result.robot_positions[-1], result.robot_goals, atol=0.3)


def test_no_robots_still_builds():
    """No tracks at all: the penalty is a plain 0.0, as before."""
    assert _penalty_anywhere(JointNLP(MPCConfig(), n_robots=0, n_humans=0).penalty_fn) == 0.0


@pytest.mark.parametrize("solver", [CMPC, DMPC])
def test_a_step_of_another_team_size_is_refused_by_name(solver):
    """A StepData of 2 robots handed to solvers built for 3 failed in numpy ("operands could not be broadcast
    together with shapes (16,) (24,) (24,)"), naming neither the robots nor the sizes."""
    cfg = MPCConfig()
    states = np.array([[0.0, 0.0, 0.0, 0.0], [1.2, 0.0, 0.0, 0.0]])
    data = StepData(states, np.zeros((2, 2)), states[:, :2] + [0.0, 5.0], np.ones(2, dtype=bool))
    with pytest.raises(ValueError, match=r"^StepData holds 2 robots, but this NLP was built for 3"):
        solver(cfg, 3, 1).solve(data, lambda _: np.zeros((cfg.horizon, 1, 2)), PlanMemory(cfg).start(data))


@pytest.mark.parametrize("solver", [JointNLP, LocalNLP, CMPC, DMPC])
@pytest.mark.parametrize(
    ("n_robots", "n_humans", "named"),
    [
        (-1, 2, "n_robots"),
        (2, -1, "n_humans"),
        (2.5, 2, "n_robots"),
        (2, "7", "n_humans"),
        (True, 2, "n_robots"),
    ],
)
def test_a_team_size_that_is_no_count_is_refused_by_name(solver, n_robots, n_humans, named):
    """CMPC(cfg, -1, 2) failed in CasADi ("Dimensions must be non-negative, got -8-by-1"), 2.5 robots with
    the list of CasADi's overloads of SX.sym: neither named the size."""
    with pytest.raises(ValueError, match=rf"^{named} must be an integer >= "):
        solver(MPCConfig(), n_robots, n_humans)


@pytest.mark.parametrize("solver", [LocalNLP, DMPC])
def test_a_local_nlp_needs_a_robot(solver):
    """The local NLP is one robot's (Eq. 5): no robot failed in CasADi ("got -1-by-1")."""
    with pytest.raises(ValueError, match=r"^n_robots must be an integer >= 1 \(a local NLP is one robot's"):
        solver(MPCConfig(), 0, 2)


def test_numpy_counts_still_build():
    """Sizes from numpy (a sweep over np.arange) built before and still do, as plain ints."""
    nlp = JointNLP(MPCConfig(), np.int64(2), np.int64(1))
    assert (nlp.n_robots, nlp.n_humans) == (2, 1) and type(nlp.n_robots) is int


@pytest.mark.parametrize("solver", [JointNLP, LocalNLP, CMPC, DMPC])
@pytest.mark.parametrize(
    ("n_robots", "n_humans", "named"),
    [(10**30, 2, "n_robots"), (2, 10**12, "n_humans"), (1001, 2, "n_robots"), (2, 100_001, "n_humans")],
)
def test_a_team_past_any_nlp_is_refused_by_name(solver, n_robots, n_humans, named):
    """10**30 robots met CasADi's overloads of SX.sym, 10**12 humans std::bad_alloc, and a few zeros fewer
    built for minutes to hours before anything said so."""
    with pytest.raises(ValueError, match=rf"^{named} must be an integer in \[[01], "):
        solver(MPCConfig(), n_robots, n_humans)
