"""``SensorRange``: a policy shown the humans within a sensor's range of some robot, the others as padding,
by the rule ``crowdmpc simulate --sensor-range`` sees them (``pipelines.loop.sensing.RangeLimited``)."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import EnvSpec

import crowdsim
from crowdsim.errors import SimulationError
from crowdsim.gym_env import CrowdNavEnv
from crowdsim.gym_observation import PRESENT
from crowdsim.gym_wrappers import SensorRange, VelocityControl
from crowdsim.scenarios import Layout
from tests.crowdsim.test_gym_env import WRAPPED, checked


def test_check_env_passes_the_sensor_wrapper():
    checked(SensorRange(gym.make(crowdsim.ENV_ID, render_mode="rgb_array"), radius=2.0), expected=(WRAPPED,))
    checked(VelocityControl(SensorRange(gym.make(crowdsim.ENV_ID), radius=3)), expected=(WRAPPED,))


def test_the_humans_out_of_range_are_padding_and_the_reward_is_the_full_ones():
    """A robot at the origin; humans standing 1.9 m and 2.1 m away: behind 2 m the second is a row of zeros,
    the first is as the plain environment shows it, and so are the robot's rows and the reward."""
    point = np.array([[0.0, 1.9], [2.1, 0.0]])
    layout = Layout(np.zeros((1, 2)), np.array([[0.0, -5.0]]), point, point)
    plain = CrowdNavEnv(n_robots=1, n_humans=2)
    sensed = SensorRange(CrowdNavEnv(n_robots=1, n_humans=2), radius=2.0)
    full, _ = plain.reset(options={"layout": layout})
    seen, _ = sensed.reset(options={"layout": layout})
    robots = plain.max_robots
    np.testing.assert_array_equal(seen[:robots], full[:robots])
    np.testing.assert_array_equal(seen[robots], full[robots])
    assert full[robots + 1, PRESENT] == 1.0 and not seen[robots + 1].any()
    action = np.zeros(plain.action_space.shape)
    full_step, seen_step = plain.step(action), sensed.step(action)
    assert full_step[1:4] == seen_step[1:4]  # reward, terminated, truncated: the simulator's
    assert not seen_step[0][robots + 1].any() and seen_step[0][robots].any()


def test_the_view_is_the_closed_loops_sensor():
    """Over a seeded episode, the rows shown are those of the humans RangeLimited hands its controller."""
    from pipelines.loop.controllers import ControllerSpec, make_controller
    from pipelines.loop.sensing import RangeLimited

    env = SensorRange(CrowdNavEnv(n_humans=7), radius=3.0)
    rule = RangeLimited(make_controller(ControllerSpec("orca")), 3.0)
    obs, info = env.reset(seed=5)
    robots = env.unwrapped.max_robots
    both = set()
    for _ in range(30):
        native = info["observation"]
        shown = obs[robots : robots + native.n_humans, PRESENT] == 1.0
        np.testing.assert_array_equal(shown, rule._visible(native))
        both |= set(shown.tolist())
        obs, _, terminated, truncated, info = env.step(np.zeros(env.action_space.shape))
        if terminated or truncated:
            break
    assert both == {True, False}  # people in view and out of it, both met


@pytest.mark.parametrize("radius", [0.0, -1.0, float("inf"), float("nan"), True, "3"])
def test_a_range_that_is_no_distance_is_refused(radius):
    with pytest.raises(SimulationError, match="radius must be a finite number of metres > 0"):
        SensorRange(CrowdNavEnv(), radius=radius)


def test_it_wraps_the_crowd_environment_only():
    with pytest.raises(SimulationError, match="SensorRange wraps a CrowdNavEnv"):
        SensorRange(gym.make("CartPole-v1"), radius=3.0)


def test_a_numpy_range_is_a_range_and_velocity_control_is_not_stacked():
    """np.int64(3) was refused as "a finite number of metres > 0"; a second VelocityControl took the
    velocities the first made of the user's for velocities again."""
    assert SensorRange(CrowdNavEnv(), radius=np.int64(3)).radius == 3.0
    once = VelocityControl(SensorRange(CrowdNavEnv(), radius=np.float32(2.5)))
    with pytest.raises(SimulationError, match="^VelocityControl wraps an environment that has one already$"):
        VelocityControl(once)
    with pytest.raises(SimulationError, match="has one already"):
        VelocityControl(SensorRange(once, radius=3.0))


@pytest.mark.parametrize(
    "inner, name",
    [
        (gym.wrappers.FlattenObservation, "FlattenObservation"),
        (lambda env: gym.wrappers.FrameStackObservation(env, 2), "FrameStackObservation"),
        (gym.wrappers.NormalizeObservation, "NormalizeObservation"),  # keeps the shape, not the numbers
        (lambda env: gym.wrappers.RecordEpisodeStatistics(gym.wrappers.FlattenObservation(env)), "Flatten"),
    ],
)
def test_the_range_refuses_an_observation_wrapper_below_it(inner, name):
    """Over FlattenObservation it zeroed scalars 3-7 of the flat vector (robot 0's goal) and left every
    human in view: the (rows, 7) array is the environment's own, so such wrappers go outside."""
    with pytest.raises(SimulationError, match=f"but {name}.* lies between; put observation wrappers"):
        SensorRange(inner(CrowdNavEnv()), radius=1.0)


def test_outside_the_range_a_flattened_view_is_the_ranged_view_flattened():
    ranged = SensorRange(CrowdNavEnv(n_humans=5), radius=1.0)
    flat = gym.wrappers.FlattenObservation(SensorRange(CrowdNavEnv(n_humans=5), radius=1.0))
    (rows, _), (vector, _) = ranged.reset(seed=0), flat.reset(seed=0)
    assert vector.shape == (rows.size,) and np.array_equal(vector, rows.ravel())
    assert rows[3:, PRESENT].sum() < 5  # some human is out of view, so the zeroing acted


@pytest.mark.parametrize(
    "inner, name",
    [
        (lambda env: gym.wrappers.RescaleAction(env, -1.0, 1.0), "RescaleAction"),
        (gym.wrappers.ClipAction, "ClipAction"),
    ],
)
def test_velocity_control_refuses_an_action_wrapper_below_it(inner, name):
    """Over RescaleAction(-1, 1) a command of 0.2 m/s became 0.4 m/s: its accelerations were read as
    [-1, 1] and rescaled to +-a_max once more."""
    with pytest.raises(SimulationError, match=f"but {name} lies between; put action wrappers"):
        VelocityControl(inner(CrowdNavEnv()))


def test_an_action_wrapper_outside_velocity_control_takes_its_velocities():
    env = gym.wrappers.RescaleAction(VelocityControl(CrowdNavEnv()), -1.0, 1.0)
    env.reset(seed=0)
    env.step(np.full(env.action_space.shape, 0.2))  # 0.2 of v_max = 1 m/s: 0.2 m/s
    base = env.unwrapped
    assert np.allclose(base.observation.robot_velocities, 0.2)


def test_the_readmes_chain_for_an_rl_library_passes_check_env():
    """README.md, "With an RL library": the project's wrappers inside, gymnasium's outside, plain data in.
    gymnasium warns of the float64 bounds cast to float32 when the wrapper is made and in check_env."""
    env = gym.make(crowdsim.ENV_ID, config={"profile": "paper"}, max_episode_steps=50)
    env = SensorRange(VelocityControl(env), radius=3.0)
    env = gym.wrappers.RescaleAction(env, -1.0, 1.0)
    with pytest.warns(UserWarning, match="precision lowered by casting to float32"):  # gymnasium's, on bounds
        env = gym.wrappers.DtypeObservation(gym.wrappers.FlattenObservation(env), np.float32)
    checked(env, expected=(WRAPPED, "precision lowered by casting to float32"))
    obs, _ = env.reset(seed=0)
    assert obs.dtype == np.float32 and obs.shape == (8 * 7,)


def test_the_wrappers_spec_of_numpys_numbers_is_written_as_json():
    """gain=np.float32(2.0) and radius=np.int64(3) were recorded in env.spec as given: spec.to_json() raised
    "TypeError: Object of type float32 is not JSON serializable"."""
    env = SensorRange(
        VelocityControl(gym.make(crowdsim.ENV_ID, n_humans=2), gain=np.float32(2.0)), radius=np.int64(3)
    )
    rebuilt = gym.make(EnvSpec.from_json(env.spec.to_json()))
    assert (rebuilt.radius, rebuilt.env.gain) == (3.0, 2.0)
