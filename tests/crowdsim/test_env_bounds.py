"""EnvConfig's upper bounds: a step within the episode, times, lengths and speeds far above any crowd but low
enough that the simulator and the controllers stay finite; the profiles' values stay valid. And what every
numeric setting of the settings classes takes: real numbers, numpy's too, never a bool."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from crowdsim.baselines import StraightController
from crowdsim.env import CrowdEnv
from crowdsim.env_config import ENV_BOUNDS, EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.gym_env import CrowdNavEnv
from crowdsim.gym_reward import RewardConfig
from crowdsim.orca import OrcaParams
from crowdsim.profiles import PROFILES, make_env_config
from crowdsim.world import LEAST, MIN_DT, WorldFacts


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
        ({"dt": 1e-7}, "EnvConfig.dt must be at least 1e-06 s, got 1e-07"),
        ({"spawn_separation": 100.5}, "EnvConfig.spawn_separation must be at most 100 m, got 100.5"),
        ({"dt": 5e-324}, "EnvConfig.dt must be at least 1e-06 s, got 4.94066e-324"),
        ({"time_limit": 1e308}, "EnvConfig.time_limit must be at most 86400 s, got 1e+308"),
        ({"radius": 1e308}, "EnvConfig.radius must be at most 10 m, got 1e+308"),
        ({"v_pref": 1e300}, "EnvConfig.v_pref must be at most 100 m/s, got 1e+300"),
        ({"v_max": 101.0}, "EnvConfig.v_max must be at most 100 m/s, got 101"),
        ({"a_max": 1e308}, "EnvConfig.a_max must be at most 1000 m/s^2, got 1e+308"),
        ({"spawn_separation": 1e308}, "EnvConfig.spawn_separation must be at most 100 m, got 1e+308"),
        ({"orca_radius_margin": float("inf")}, "EnvConfig.orca_radius_margin must be in [0, 10] m, got inf"),
        ({"orca_radius_margin": 11.0}, "EnvConfig.orca_radius_margin must be in [0, 10] m, got 11.0"),
        # just past a bound: ':g' rounded each onto it ('must be at most 10 m, got 10')
        ({"radius": 10.000001}, "EnvConfig.radius must be at most 10 m, got 10.000001"),
        ({"time_limit": 86400.0001}, "EnvConfig.time_limit must be at most 86400 s, got 86400.0001"),
        ({"dt": 9.999999e-7}, "EnvConfig.dt must be at least 1e-06 s, got 9.999999e-07"),
        ({"dt": 40.0000001}, "EnvConfig.dt must be at most time_limit = 40 s, got 40.0000001"),
        (
            {"spawn_separation": 100.000001},
            "EnvConfig.spawn_separation must be at most 100 m, got 100.000001",
        ),
    ],
)
def test_values_beyond_the_bounds_are_refused_in_one_compact_line(settings, message):
    with pytest.raises(SimulationError) as exc:
        EnvConfig(**settings)
    assert str(exc.value) == message


@pytest.mark.parametrize(
    "make, message",
    [
        (
            lambda: EnvConfig(history_len=10**6),
            "EnvConfig.history_len must be an int in [1, 1000], got 1000000",
        ),
        (
            lambda: CrowdNavEnv(config={"history_len": 1001}),
            "EnvConfig.history_len must be an int in [1, 1000], got 1001",
        ),
        (lambda: WorldFacts(obs_len=1001), "WorldFacts.obs_len must be an int in [1, 1000], got 1001"),
        (
            lambda: OrcaParams(max_neighbors=1001),
            "OrcaParams.max_neighbors must be an int in [0, 1000], got 1001",
        ),
        (
            lambda: EnvConfig(dt=0.01, time_limit=1001.01),
            "EnvConfig.time_limit must be at most 100000 steps of dt = 0.01 s, got 1001.01 s (1e+05 steps)",
        ),
    ],
)
def test_the_sizes_of_the_work_are_bounded_from_python_as_the_cli_bounds_them(make, message):
    """10**6 history rows took 21 s and 860 MB for three steps when only the CLI refused them: the
    library refuses what the config schema does (pipelines.config.keys.MOST reads these bounds)."""
    with pytest.raises(SimulationError) as exc:
        make()
    assert str(exc.value) == message


def test_the_largest_sizes_of_the_work_are_accepted():
    # paper profile, 1 s margin: steps start at k * 0.01 s < 1000 s, k = 0..99999
    assert EnvConfig(dt=0.01, time_limit=1001.0).max_steps == 100_000
    assert EnvConfig(history_len=1000).history_len == WorldFacts(obs_len=1000).obs_len == 1000
    assert OrcaParams(max_neighbors=1000).max_neighbors == 1000


def test_the_edges_of_the_closed_ranges_are_accepted():
    """No ORCA radius margin, no spawn separation (humans may spawn touching) and the largest separation are
    valid settings, kept as given."""
    config = EnvConfig(orca_radius_margin=0.0, spawn_separation=0.0)
    assert (config.orca_radius_margin, config.spawn_separation) == (0.0, 0.0)
    assert EnvConfig(spawn_separation=100.0, orca_radius_margin=10.0).spawn_separation == 100.0


def test_world_facts_name_each_setting_in_its_place():
    # Distinct values, so that two settings exchanged (v_pref and v_max are both 1 m/s by default) show.
    config = EnvConfig(dt=0.2, history_len=6, radius=0.25, v_pref=0.8, v_max=1.2, a_max=0.7)
    world = config.world()
    assert world == WorldFacts(dt=0.2, obs_len=6, radius=0.25, v_pref=0.8, v_max=1.2, a_max=0.7)
    assert EnvConfig.from_world(world) == config


def _extreme_env() -> tuple[CrowdEnv, dict[str, float]]:
    most = {name: bound for name, (bound, _) in ENV_BOUNDS.items() if name != "radius"}
    return CrowdEnv(EnvConfig(dt=most["time_limit"], timeout_margin=0.0, **most)), most


def test_the_extremes_accepted_keep_the_straight_controller_finite():
    """The largest step, speeds and bounds allowed: one episode step stays finite (dt = 1e308 overflowed) and
    is the double integrator's: s' = s + tau^2/2 a, v' = tau a from rest, a within the bounds unclipped."""
    env, most = _extreme_env()
    obs = env.reset(seed=0, scenario="circle", n_humans=5, n_robots=3)
    controller = StraightController(v_max=most["v_max"], a_max=most["a_max"])
    a = controller.act(obs).accelerations
    start = obs.robot_positions
    obs, _, info = env.step(a)
    assert np.isfinite(obs.robot_positions).all() and np.isfinite(obs.human_positions).all()
    tau = 86_400.0
    # from rest the bounds are +-min(a_max, v_max / tau) = +-100 / 86400 m/s^2; the controller asks for
    # about 2 x 10 m / tau^2 = 2.7e-9 m/s^2 north (a 10 m trip in one step), within them
    assert np.abs(a).max() < 100 / tau and not info["clipped"].any()
    np.testing.assert_array_equal(info["accelerations"], a)
    np.testing.assert_allclose(obs.robot_positions, start + tau**2 / 2 * a, rtol=1e-12, atol=0)
    np.testing.assert_allclose(obs.robot_velocities, tau * a, rtol=1e-12, atol=0)
    # so each robot lands (almost) on its goal 10 m north, at about 2 x 10 m / tau = 2.3e-4 m/s
    np.testing.assert_allclose(obs.robot_positions, obs.robot_goals, rtol=0, atol=1e-3)
    np.testing.assert_allclose(obs.robot_velocities[:, 1], 20 / tau, rtol=1e-3)
    with pytest.raises(SimulationError, match="at most 100000 steps of dt = 1e-06 s, got 86400 s"):
        EnvConfig(dt=MIN_DT, time_limit=most["time_limit"])  # 8.6e10 steps: finite, but days of stepping


def test_the_extremes_clip_the_acceleration_to_the_speed_bound():
    """tau = 86400 s, v_max = 100 m/s, a_max = 1000 m/s^2, from rest: each component of a is clipped to
    +-v_max / tau = +-1/864 m/s^2 (the speed bound, far below a_max); then s' = s + tau^2/2 a, v' = tau a."""
    env, _ = _extreme_env()
    start = env.reset(seed=0, scenario="circle", n_humans=5, n_robots=3).robot_positions
    asked = np.array([[1000.0, -1000.0], [5e-4, 0.0], [-1e-3, 2e-3]])
    obs, _, info = env.step(asked)
    applied = np.array([[1 / 864, -1 / 864], [5e-4, 0.0], [-1e-3, 1 / 864]])
    np.testing.assert_allclose(info["accelerations"], applied, rtol=1e-15, atol=0)
    assert info["clipped"].tolist() == [True, False, True]
    # v' = 86400 a: (100, -100), (43.2, 0), (-86.4, 100) m/s
    velocities = [[100.0, -100.0], [43.2, 0.0], [-86.4, 100.0]]
    np.testing.assert_allclose(obs.robot_velocities, velocities, rtol=1e-12, atol=0)
    # s' - s = 86400^2 / 2 a: 4.32e6 m at the bound, 1866240 m for 5e-4, -3732480 m for -1e-3
    moved = [[4.32e6, -4.32e6], [1_866_240.0, 0.0], [-3_732_480.0, 4.32e6]]
    np.testing.assert_allclose(obs.robot_positions - start, moved, rtol=1e-12, atol=1e-6)


# Every numeric setting of the simulator's settings classes, with its kind: one check for all (errors.py).
NUMERIC_SETTINGS = [
    *((EnvConfig, name, float) for name in ("dt", *ENV_BOUNDS, "orca_radius_margin", "timeout_margin")),
    (EnvConfig, "spawn_separation", float),
    (EnvConfig, "history_len", int),
    *((WorldFacts, f.name, int if f.name == "obs_len" else float) for f in fields(WorldFacts)),
    (OrcaParams, "neighbor_dist", float),
    (OrcaParams, "max_neighbors", int),
    (OrcaParams, "time_horizon", float),
    *((RewardConfig, f.name, float) for f in fields(RewardConfig)),
]


@pytest.mark.parametrize("cls, name, kind", NUMERIC_SETTINGS)
def test_a_numeric_setting_takes_numpy_scalars_as_plain_numbers(cls, name, kind):
    # np.float32(0.4) and np.int64(9) were refused ("must be a finite number > 0, got np.float32(0.4)"); they
    # are stored as Python's float and int, so no numpy type reaches the simulator's arithmetic.
    default = getattr(cls(), name)
    scalar = np.int64(default) if kind is int else np.float32(default)
    value = getattr(cls(**{name: scalar}), name)
    assert type(value) is kind and value == kind(scalar)


@pytest.mark.parametrize("cls, name, kind", NUMERIC_SETTINGS)
@pytest.mark.parametrize("bad", [True, "10", None])
def test_a_numeric_setting_refuses_what_is_no_number_naming_it(cls, name, kind, bad):
    # True was taken as 1 (dt = 1 s, 98 steps from timeout_margin=True); "10" raised a TypeError from a
    # comparison that named no field.
    with pytest.raises(SimulationError, match=rf"^{cls.__name__}\.{name} must be .*, got {bad!r}$"):
        cls(**{name: bad})


@pytest.mark.parametrize("cls", [WorldFacts, EnvConfig])
@pytest.mark.parametrize("name", ["dt", "radius", "v_pref", "v_max", "a_max"])
def test_a_world_fact_below_its_least_value_is_refused(cls, name):
    """5e-324 passed "> 0": with [world] radius = 5e-324 a straight-line run reported no contact of robots
    that passed 0.07 m from people. The least values are crowdsim.world.LEAST's, taken as given."""
    least, unit = LEAST[name]
    short = {"time_limit": 0.01, "timeout_margin": 0.0} if (cls, name) == (EnvConfig, "dt") else {}
    assert getattr(cls(**{name: least}, **short), name) == least  # 1e4 steps of 1e-6 s
    with pytest.raises(SimulationError) as exc:
        cls(**{name: 5e-324})
    assert str(exc.value) == f"{cls.__name__}.{name} must be at least {least:g} {unit}, got 4.94066e-324"
