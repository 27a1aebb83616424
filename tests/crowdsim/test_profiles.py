"""Profiles, world facts and robot visibility."""

import dataclasses

import numpy as np
import pytest

from crowdsim import world
from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.orca import preferred_velocities
from crowdsim.profiles import PROFILES, VISIBILITY, make_env_config
from crowdsim.scenarios import Layout


def test_default_config_is_the_paper_profile_with_visible_robots():
    assert set(PROFILES) == {"paper", "v1"} and VISIBILITY == ("visible", "invisible")
    assert EnvConfig() == PROFILES["paper"] == make_env_config() == make_env_config("paper", "visible")
    cfg = EnvConfig()
    assert (cfg.dt, cfg.radius, cfg.v_pref, cfg.v_max, cfg.a_max) == (0.4, 0.3, 1.0, 1.0, 2.0)
    assert cfg.history_len == world.OBS_LEN == 9
    assert (cfg.profile, cfg.time_limit, cfg.timeout_margin) == ("paper", 40.0, 1.0)
    assert cfg.spawn_separation == 0.5 and 2 * cfg.radius + cfg.spawn_separation == 1.1
    assert (cfg.crossing, cfg.success_rule, cfg.robots_visible) == ("paper", "simultaneous", True)


def test_v1_profile_and_visibility():
    v1 = make_env_config("v1", "invisible")
    assert dataclasses.replace(v1, robots_visible=True) == PROFILES["v1"]
    assert (v1.profile, v1.time_limit, v1.timeout_margin, v1.spawn_separation) == ("v1", 30.0, 0.0, 0.2)
    assert (v1.crossing, v1.success_rule, v1.robots_visible) == ("v1", "first_reach", False)
    assert not make_env_config("paper", "invisible").robots_visible


def test_make_env_config_names_the_bad_value_and_the_choices():
    with pytest.raises(SimulationError, match=r"'crowdnav'.*\['paper', 'v1'\]"):
        make_env_config("crowdnav")
    with pytest.raises(SimulationError, match=r"'hidden'.*\['visible', 'invisible'\]"):
        make_env_config("paper", "hidden")
    # a YAML list or mapping (gym.make's config) is no name: refused as one, not TypeError "unhashable"
    with pytest.raises(SimulationError, match=r"unknown profile \['paper'\]; choose from"):
        make_env_config(["paper"])  # type: ignore[arg-type]


def _head_on(config):
    """A human 4 m west of a standing robot, walking east 10 cm off the robot's line; its velocities."""
    env = CrowdEnv(config)
    env.reset_layout(
        Layout(
            robot_starts=np.array([[0.0, 0.0]]),
            robot_goals=np.array([[0.0, 9.0]]),
            human_starts=np.array([[-4.0, 0.1]]),
            human_goals=np.array([[4.0, 0.1]]),
        )
    )
    velocities = []
    for _ in range(12):
        obs, _, _ = env.step(np.zeros((1, 2)))
        velocities.append(obs.human_velocities[0])
    return env.trajectory().human_positions[:-1, 0], np.array(velocities)


def test_invisible_robots_do_not_deflect_the_humans():
    positions, velocities = _head_on(make_env_config("paper", "invisible"))
    goal = np.array([[4.0, 0.1]])
    # Every step the human moves with its preferred velocity: 1 m/s east, straight through the robot.
    for p, v in zip(positions, velocities, strict=True):
        np.testing.assert_array_equal(v, preferred_velocities(p[None], goal, 1.0, stop_radius=0.3)[0])
    np.testing.assert_array_equal(velocities[:8], np.tile([1.0, 0.0], (8, 1)))
    _, seen = _head_on(make_env_config("paper", "visible"))
    assert np.linalg.norm(seen[0] - [1.0, 0.0]) > 0.5  # a visible robot makes it deviate at once
