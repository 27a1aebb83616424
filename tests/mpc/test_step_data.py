"""StepData's bound on how large its numbers (and a prediction's) may be: a finite velocity of 1e200 made the
NLP's gradient NaN at its start point and the first Fatrop solve of the step never returned."""

import dataclasses
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mpc.cmpc import finite_prediction
from mpc.config import MPC_BOUNDS, MPC_LEAST, MPCConfig
from mpc.costs import make_track, potential
from mpc.step_data import MAX_MAGNITUDE, StepData

ROOT = Path(__file__).resolve().parents[2]


def two_robots() -> StepData:
    states = np.array([[0.0, 0.0, 0.5, 0.5], [2.0, 0.0, -0.5, 0.5]])
    return StepData(states, np.zeros((2, 2)), np.array([[0.0, 5.0], [2.0, 5.0]]), np.ones(2, dtype=bool))


@pytest.mark.parametrize(
    ("field", "column", "value", "message"),
    [
        ("states", 2, 1e200, "states: robot 1's velocity 1e+200 m/s exceeds 1e+09 in magnitude"),
        ("states", 3, -1e155, "states: robot 1's velocity -1e+155 m/s exceeds 1e+09"),
        ("states", 0, 1e300, "states: robot 1's position 1e+300 m exceeds 1e+09"),
        ("goals", 1, -2e9, "goals: robot 1's goal -2e+09 m exceeds 1e+09"),
        ("targets", 0, 1e300, "targets: robot 1's target 1e+300 m exceeds 1e+09"),
        ("last_actions", 1, 1e200, "last_actions: robot 1's last action 1e+200 m/s^2 exceeds 1e+09"),
    ],
)
def test_numbers_beyond_the_bound_are_refused_naming_robot_and_quantity(field, column, value, message):
    data = two_robots()
    values = np.array(data.goals if field == "targets" else getattr(data, field))
    values[1, column] = value
    with pytest.raises(ValueError) as refused:
        dataclasses.replace(data, **{field: values})
    text = str(refused.value)
    assert text.startswith(message) and "\n" not in text
    assert text.endswith(
        "the most the MPC takes (mpc.step_data.MAX_MAGNITUDE; far larger values overflow the NLP's squares)"
    )


def test_numbers_at_the_bound_are_taken():
    data = two_robots()
    edge = np.array([MAX_MAGNITUDE, -MAX_MAGNITUDE])
    taken = dataclasses.replace(
        data,
        states=np.tile(np.concatenate([edge, edge]), (2, 1)),
        last_actions=np.tile(edge, (2, 1)),
        goals=np.tile(-edge, (2, 1)),
        targets=np.tile(edge, (2, 1)),
    )
    assert np.abs(taken.states).max() == MAX_MAGNITUDE


def test_a_prediction_beyond_the_bound_is_not_planned_with():
    """A human predicted at -1e308 made the gradient NaN (squares inf, inf - inf); such a prediction is now
    what a NaN one is: the step falls back."""
    shape = (4, 1, 2)
    assert finite_prediction(np.full(shape, -1e308), shape) is None
    assert finite_prediction(np.full(shape, 2 * MAX_MAGNITUDE), shape) is None
    assert finite_prediction(np.full(shape, np.nan), shape) is None
    np.testing.assert_array_equal(finite_prediction(np.full(shape, -MAX_MAGNITUDE), shape), -MAX_MAGNITUDE)


SOLVE = """
import sys
sys.path.insert(0, {root!r})
import numpy as np
from mpc.cmpc import CMPC
from mpc.config import MPCConfig
from mpc.fallback import PlanMemory
from tests.mpc.test_step_data import two_robots
cfg, data = MPCConfig(), two_robots()
far = lambda future: np.full((cfg.horizon, 1, 2), -1e308)
result = CMPC(cfg, 2, 1).solve(data, far, PlanMemory(cfg).start(data))
print(result.status, result.solved, result.solves)
"""


def test_a_step_predicting_a_human_at_minus_1e308_returns():
    """In a process of its own, under a time limit: the Fatrop solve this step started never returned."""
    done = subprocess.run(
        [sys.executable, "-c", SOLVE.format(root=str(ROOT))], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["nan_prediction", "False", "0"]


@pytest.mark.parametrize("seed", range(3))
def test_at_the_bound_the_nlp_stays_far_from_overflow(seed):
    """The potential, its gradient and exact Hessian in the accelerations, with MPCConfig at every bound (and
    least value) together, starts, velocities, goals, last actions and humans at +-MAX_MAGNITUDE, some robots
    on their goals (Eq. 7's weight w_goal / delta), accelerations up to 10 a_max (an interior-point iterate):
    finite, and small enough that the solvers' squares of them are too (mpc/step_data.py's comment)."""
    bounds = {name: most for name, (most, _) in MPC_BOUNDS.items()}
    cfg = MPCConfig(**(bounds | {k: v for k, (v, _) in MPC_LEAST.items()}))
    h = cfg.horizon
    u = ca.SX.sym("u", 2, 2 * h)
    starts, humans = ca.SX.sym("x", 4, 2), ca.SX.sym("h", 2, h)
    goals, last = ca.SX.sym("g", 2, 2), ca.SX.sym("l", 2, 2)
    tracks = [
        make_track(starts[:, i], u[:, i * h : (i + 1) * h], last[:, i], goals[:, i], cfg.dt) for i in (0, 1)
    ]
    cost = cfg.cost_scale * potential(tracks, ca.DM([cfg.w_floc]), humans, 1, cfg)
    hessian, gradient = ca.hessian(cost, ca.vec(u))
    f = ca.Function("f", [ca.vec(u), starts, humans, goals, last], [cost, gradient, hessian])
    rng = np.random.default_rng(seed)
    for draw in range(20):
        state = rng.choice([-MAX_MAGNITUDE, MAX_MAGNITUDE], (4, 2))
        goal = state[0:2] if draw % 2 else rng.choice([-MAX_MAGNITUDE, MAX_MAGNITUDE], (2, 2))
        inputs = (
            rng.uniform(-10.0, 10.0, 4 * h) * cfg.a_max,
            state,
            rng.choice([-MAX_MAGNITUDE, MAX_MAGNITUDE], (2, h)),
            goal,
            rng.choice([-MAX_MAGNITUDE, MAX_MAGNITUDE], (2, 2)),
        )
        for out in f(*inputs):
            assert np.all(np.abs(out.full()) < 1e100)
