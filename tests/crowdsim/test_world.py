"""crowdsim.world is the one source of the shared facts: the other packages name its values, not copies."""

import inspect

from crowdsim import env, gym_env, metrics, plotting, world
from mpc import config
from predictors import real_data


def test_table_i_values():
    assert (world.DT, world.RADIUS, world.D_MIN, world.D_FLOCK) == (0.4, 0.3, 0.8, 1.2)
    assert (world.HORIZON, world.PAPER_ROBOTS) == (4, 3)


def test_the_other_packages_read_world():
    assert metrics.COLLISION_DISTANCE is world.D_MIN
    assert config.PAPER_ROBOTS is world.PAPER_ROBOTS
    assert config.MPCConfig().horizon == world.HORIZON
    assert real_data.HORIZON == world.HORIZON
    assert config.GUIDANCE_MODES == ("none", "standing")


def test_defaults_follow_world():
    assert inspect.signature(env.CrowdEnv.reset).parameters["n_robots"].default == world.PAPER_ROBOTS
    assert inspect.signature(plotting.plot_episode).parameters["radius"].default == world.RADIUS
    assert gym_env.CrowdNavEnv.metadata["render_fps"] == 1.0 / world.DT == 2.5
