"""EnvConfig's upper bounds: a step within the episode, times, lengths and speeds far above any crowd but low
enough that the simulator and the controllers stay finite; the profiles' values stay valid."""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim.baselines import StraightController
from crowdsim.env import ENV_BOUNDS, MIN_DT, CrowdEnv, EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.profiles import PROFILES, make_env_config


@pytest.mark.parametrize("profile", sorted(PROFILES))
@pytest.mark.parametrize("visibility", ["visible", "invisible"])
def test_the_profiles_are_within_the_bounds(profile, visibility):
    config = make_env_config(profile, visibility)
    assert EnvConfig(**{f: getattr(config, f) for f in config.__dataclass_fields__}) == config


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"dt": 1e308}, "EnvConfig.dt must be at most time_limit = 40 s, got 1e+308"),
        ({"dt": 41.0}, "EnvConfig.dt must be at most time_limit = 40 s, got 41"),
        ({"dt": 1e-300}, "EnvConfig.dt must be at least 1e-06 s, got 1e-300"),
        ({"dt": 5e-324}, "EnvConfig.dt must be at least 1e-06 s, got 4.94066e-324"),
        ({"time_limit": 1e308}, "EnvConfig.time_limit must be at most 86400 s, got 1e+308"),
        ({"radius": 1e308}, "EnvConfig.radius must be at most 10 m, got 1e+308"),
        ({"v_pref": 1e300}, "EnvConfig.v_pref must be at most 100 m/s, got 1e+300"),
        ({"v_max": 101.0}, "EnvConfig.v_max must be at most 100 m/s, got 101"),
        ({"a_max": 1e308}, "EnvConfig.a_max must be at most 1000 m/s^2, got 1e+308"),
        ({"spawn_separation": 1e308}, "EnvConfig.spawn_separation must be at most 100 m, got 1e+308"),
        ({"orca_radius_margin": float("inf")}, "EnvConfig.orca_radius_margin must be in [0, 10] m, got inf"),
        ({"orca_radius_margin": 11.0}, "EnvConfig.orca_radius_margin must be in [0, 10] m, got 11.0"),
    ],
)
def test_values_beyond_the_bounds_are_refused_in_one_compact_line(settings, message):
    with pytest.raises(SimulationError) as exc:
        EnvConfig(**settings)
    assert str(exc.value) == message


def test_the_extremes_accepted_keep_the_straight_controller_finite():
    """The largest step, speeds and bounds allowed: one episode step stays finite (dt = 1e308 overflowed)."""
    most = {name: bound for name, (bound, _) in ENV_BOUNDS.items() if name != "radius"}
    env = CrowdEnv(EnvConfig(dt=most["time_limit"], timeout_margin=0.0, **most))
    obs = env.reset(seed=0, scenario="circle", n_humans=5, n_robots=3)
    controller = StraightController(v_max=most["v_max"], a_max=most["a_max"])
    obs, _, _ = env.step(controller.act(obs).accelerations)
    assert np.isfinite(obs.robot_positions).all() and np.isfinite(obs.human_positions).all()
    assert EnvConfig(dt=MIN_DT, time_limit=most["time_limit"]).max_steps > 0  # 8.6e10: still finite
