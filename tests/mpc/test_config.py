"""MPCConfig: Table I defaults and validation of every field."""

import math

import pytest

from mpc.config import MPCConfig
from mpc.errors import MPCConfigError


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
