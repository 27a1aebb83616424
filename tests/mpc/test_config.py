"""MPCConfig: Table I defaults and validation of every field."""

import math
import re

import casadi as ca
import numpy as np
import pytest

from mpc.cmpc import CMPC
from mpc.config import MPC_BOUNDS, MPC_LEAST, MPCConfig
from mpc.costs import make_track, potential
from mpc.dmpc import DMPC
from mpc.errors import MPCConfigError
from mpc.nlp import JointNLP, LocalNLP, check_solvable


def test_defaults_are_table_one():
    cfg = MPCConfig()
    table_one = {
        "horizon": 4,
        "dt": 0.4,
        "w_goal": 10.0,
        "w_acce": 0.1,
        "w_jerk": 0.1,
        "w_coll": 1e7,
        "w_floc": 10.0,
        "v_max": 1.0,
        "a_max": 2.0,
        "rho": 0.5,
        "d_min": 0.8,
        "mu": 30.0,
        "j_max": 10,
        "xi": 1e-3,
        "epsilon": 1e-3,
    }
    for name, value in table_one.items():
        assert getattr(cfg, name) == value, name
    assert cfg.d_flock == 1.2 and cfg.delta == 1e-3


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("horizon", 0),
        ("horizon", 2.5),
        ("horizon", True),
        ("horizon", 101),  # from Python as from a config file: a build of minutes, deaf to Ctrl-C
        ("j_max", 0),
        ("solver_max_iter", -1),
        ("dt", 0.0),
        ("w_goal", -1.0),
        ("w_coll", 0.0),
        ("a_max", 0.0),
        ("v_max", -1.0),
        ("mu", math.nan),
        ("d_min", math.inf),
        ("xi", 0.0),
        ("epsilon", -1e-3),
        ("delta", 0.0),
        ("d_flock", 0.0),
        ("cost_scale", 0.0),
        ("solver_tol", 0.0),
        ("time_limit_s", 0.0),
        ("w_acce", -0.1),
        ("w_jerk", -0.1),
        ("w_floc", -1.0),
        ("rho", -0.5),
        ("w_goal", "10"),
        ("warm_start", 1),
        ("multi_start", "yes"),
        ("dmpc_parallel", "processes"),
        ("coupled_mode", "second_order"),
    ],
)
def test_invalid_values_are_named(field, value):
    with pytest.raises(MPCConfigError, match=field) as info:
        MPCConfig(**{field: value})
    assert repr(value) in str(info.value)


def test_zero_is_allowed_where_a_term_may_be_switched_off():
    cfg = MPCConfig(w_floc=0.0, w_acce=0.0, w_jerk=0.0, rho=0.0, solver_max_iter=0)
    assert cfg.w_floc == 0.0 and cfg.solver_max_iter == 0


def test_replace_validates_and_rejects_unknown_fields():
    assert MPCConfig().replace(horizon=6).horizon == 6
    with pytest.raises(MPCConfigError, match="horizon"):
        MPCConfig().replace(horizon=0)
    with pytest.raises(MPCConfigError, match="unknown MPC config field"):
        MPCConfig().replace(horizn=6)


def test_numpy_scalars_are_stored_as_pythons():
    """As EnvConfig: np.int64(4) was refused as "horizon must be an integer >= 1", np.True_ as no bool."""
    config = MPCConfig(
        horizon=np.int64(4), d_min=np.float32(0.5), warm_start=np.True_, human_margins=[np.float64(0.1)] * 4
    )
    assert config == MPCConfig(d_min=float(np.float32(0.5)), human_margins=(0.1,) * 4)
    assert [type(v) for v in (config.horizon, config.d_min, config.warm_start)] == [int, float, bool]
    assert all(type(m) is float for m in config.human_margins)
    with pytest.raises(MPCConfigError, match=r"^horizon must be an integer >= 1, got 4.5$"):
        MPCConfig(horizon=np.float64(4.5))


def test_human_margins_are_validated_and_kept_as_a_tuple():
    assert MPCConfig().human_margins == () and MPCConfig().human_margin(3) == 0.0
    cfg = MPCConfig(human_margins=[0.05, 0.1, 0.15, 0.2])  # a JSON round trip gives a list
    assert cfg.human_margins == (0.05, 0.1, 0.15, 0.2) and cfg.human_margin(1) == 0.1
    assert cfg == MPCConfig(human_margins=(0.05, 0.1, 0.15, 0.2)) and hash(cfg) == hash(
        MPCConfig(human_margins=(0.05, 0.1, 0.15, 0.2))
    )
    for bad, match in (
        ((0.1, 0.2), "one margin per horizon step"),
        ((0.1, -0.1, 0.1, 0.1), ">= 0"),
        ((0.1, float("nan"), 0.1, 0.1), "finite"),
        (0.3, "sequence"),
    ):
        with pytest.raises(MPCConfigError, match=match):
            MPCConfig(human_margins=bad)


@pytest.mark.parametrize("field", sorted(MPC_BOUNDS))
@pytest.mark.parametrize("nlp", [JointNLP, LocalNLP])
def test_numbers_that_enter_the_nlp_are_bounded(field, nlp):
    """rho = 1e300 passed, made the exact Hessian Inf, and a Fatrop solve (no wall-time limit) ran on: an
    NLP is not built with it. MPCConfig holds it (a config a sweep folder recorded reads back;
    tests/pipelines)."""
    most, _ = MPC_BOUNDS[field]
    check_solvable(MPCConfig(**{field: most}))
    beyond = MPCConfig(**{field: 1e300})
    assert getattr(beyond, field) == 1e300
    shown = re.escape(f"{most:g}")
    with pytest.raises(MPCConfigError, match=rf"^{field} must be at most {shown}.*, got 1e\+300$"):
        nlp(beyond, 2, 1)


@pytest.mark.parametrize("field", sorted(MPC_LEAST))
@pytest.mark.parametrize("nlp", [JointNLP, LocalNLP])
def test_numbers_that_enter_the_nlp_have_a_least_value(field, nlp):
    """mu = 1e-300 passed "> 0" and overflowed every pair's penalty, log(2) / mu, to inf: an NLP is not built
    with it. MPCConfig holds it (a config a sweep folder recorded reads back; tests/pipelines)."""
    least, _ = MPC_LEAST[field]
    check_solvable(MPCConfig(**{field: least}))
    below = MPCConfig(**{field: 1e-300})
    assert getattr(below, field) == 1e-300
    with pytest.raises(
        MPCConfigError, match=rf"^{field} must be at least {re.escape(f'{least:g}')}.*, got 1e-300$"
    ):
        nlp(below, 2, 1)


@pytest.mark.parametrize("nlp", [JointNLP, LocalNLP])
def test_a_step_time_below_a_nanosecond_is_refused_as_the_nlp_is_built(nlp):
    """time_limit_s = 5e-324 passed "> 0": no budget the steps' clock (perf_counter) or IPOPT's
    max_wall_time tells from 1e-9, the least the tests cut a step at once with."""
    check_solvable(MPCConfig(time_limit_s=1e-9))
    with pytest.raises(MPCConfigError) as exc:
        nlp(MPCConfig(time_limit_s=5e-324), 2, 1)
    assert str(exc.value) == "time_limit_s must be at least 1e-09 s, got 5e-324"


@pytest.mark.parametrize("solver", [CMPC, DMPC])
def test_a_solver_is_not_built_beyond_a_bound(solver):
    """What a Python caller builds with an MPCConfig beyond a bound is refused before any solve."""
    with pytest.raises(MPCConfigError, match=r"^rho must be at most 1000 s\^2, got 2000.0$"):
        solver(MPCConfig(rho=2000.0), 3, 2)


@pytest.mark.parametrize(
    ("field", "below", "message"),
    [
        ("dt", 5e-324, "dt must be at least 1e-06 s, got 5e-324"),
        ("dt", 1e-300, "dt must be at least 1e-06 s, got 1e-300"),
        ("v_max", 1e-12, "v_max must be at least 1e-06 m/s, got 1e-12"),
        ("a_max", 1e-300, "a_max must be at least 1e-06 m/s^2, got 1e-300"),
        ("d_flock", 5e-324, "d_flock must be at least 1e-06 m, got 5e-324"),
    ],
)
@pytest.mark.parametrize("solver", [CMPC, DMPC])
def test_the_worlds_facts_and_d_flock_have_least_values_from_python(field, below, message, solver):
    """A run takes tau, v_max and a_max from the world, which refuses below crowdsim.world.LEAST, but an
    MPCConfig built in Python took any float > 0 and its MPC never moved, every step "ok" (tau = 1e-300: a
    horizon of 4e-300 s; 5e-324 overflowed the plan's clipping, (v_max - v) / tau); d_flock = 5e-324 ran too.
    The same least values as the world's, from there."""
    from crowdsim import world

    if field != "d_flock":
        assert MPC_LEAST[field][0] == world.LEAST[field][0]
    least = MPC_LEAST[field][0]
    solver(MPCConfig(**{field: least}), 2, 1)
    with pytest.raises(MPCConfigError) as exc:
        solver(MPCConfig(**{field: below}), 2, 1)
    assert str(exc.value) == message


def test_delta_has_a_least_value():
    """Eq. 7 weighs a robot on its goal by w_goal / delta: delta = 1e-300 passed "> 0", and with w_goal = 1e12
    the weight overflowed, the gradient was NaN and a Fatrop solve never returned."""
    with pytest.raises(MPCConfigError, match=r"^delta must be at least 1e-40, got 1e-300$"):
        CMPC(MPCConfig(delta=1e-300, w_goal=1e12), 2, 1)


@pytest.mark.parametrize("least", [False, True], ids=["most", "least_and_most"])
def test_at_every_bound_together_the_nlp_stays_finite(least):
    """The potential, its gradient and exact Hessian in the accelerations (what Fatrop and IPOPT evaluate),
    with every bounded number at its bound, at points beyond the bounds an interior-point iterate may reach
    (2 robots, 1 human; robot 0 starts on its goal, where Eq. 7 weighs by w_goal / delta: delta = 1e-300
    with w_goal = 1e12 made the gradient NaN there, and the Fatrop solve never returned)."""
    bounds = {name: most for name, (most, _) in MPC_BOUNDS.items()}
    cfg = MPCConfig(**(bounds | ({k: v for k, (v, _) in MPC_LEAST.items()} if least else {})))
    h = cfg.horizon
    u = ca.SX.sym("u", 2, 2 * h)
    starts, humans = ca.SX.sym("x", 4, 2), ca.SX.sym("h", 2, h)
    goals = starts[0:2, :] + ca.horzcat(ca.DM([0.0, 0.0]), ca.DM([0.0, 6.0]))
    no_action = ca.DM.zeros(2, 1)
    tracks = [
        make_track(starts[:, i], u[:, i * h : (i + 1) * h], no_action, goals[:, i], cfg.dt) for i in (0, 1)
    ]
    cost = cfg.cost_scale * potential(tracks, ca.DM([cfg.w_floc]), humans, 1, cfg)
    hessian, gradient = ca.hessian(cost, ca.vec(u))
    f = ca.Function("f", [ca.vec(u), starts, humans], [cost, gradient, hessian])
    rng = np.random.default_rng(0)
    for _ in range(20):
        accels = rng.uniform(-10.0, 10.0, 4 * h) * cfg.a_max
        state = np.vstack([rng.uniform(-100.0, 100.0, (2, 2)), rng.uniform(-1.0, 1.0, (2, 2)) * cfg.v_max])
        for out in f(accels, state, rng.uniform(-100.0, 100.0, (2, h))):
            assert np.isfinite(out.full()).all()


@pytest.mark.parametrize(
    "field, most, beyond, message",
    [
        ("horizon", 100, 101, "horizon must be an integer in [1, 100], got 101"),
        ("j_max", 1000, 10**9, "j_max must be an integer in [1, 1000], got 1000000000"),
        # the solvers take max_iter as a C int: 2**31 made IPOPT refuse its options, 2**32 wrapped to 0
        (
            "solver_max_iter",
            100_000,
            2**31,
            f"solver_max_iter must be an integer in [0, 100000], got {2**31}",
        ),
        (
            "solver_max_iter",
            100_000,
            2**32,
            f"solver_max_iter must be an integer in [0, 100000], got {2**32}",
        ),
        ("time_limit_s", 3600.0, 1e9, "time_limit_s must be in (0, 3600] s, got 1000000000.0"),
        ("time_limit_s", 3600.0, 3600.5, "time_limit_s must be in (0, 3600] s, got 3600.5"),
    ],
)
def test_the_sizes_of_the_work_are_bounded_from_python_as_the_cli_bounds_them(field, most, beyond, message):
    """MPCConfig(j_max=10**9) or time_limit_s=1e9 was taken from Python, where the config schema refuses
    anything past 1000 iterations or an hour a step: the library holds those bounds now (mpc.sizes), and the
    CLI reads them from there."""
    assert getattr(MPCConfig(**{field: most}), field) == most
    with pytest.raises(MPCConfigError) as exc:
        MPCConfig(**{field: beyond})
    assert str(exc.value) == message
