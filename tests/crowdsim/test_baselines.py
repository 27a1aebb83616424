"""The two baseline controllers in the environment."""

import numpy as np

from crowdsim.baselines import OrcaController, StraightController
from crowdsim.env import CrowdEnv
from crowdsim.metrics import episode_metrics
from crowdsim.scenarios import Layout
from pipelines.loop.controllers import ControlOutput


def layout(robot_starts, robot_goals, human_starts=(), human_goals=()):
    return Layout(
        robot_starts=np.array(robot_starts, dtype=float),
        robot_goals=np.array(robot_goals, dtype=float),
        human_starts=np.array(human_starts, dtype=float).reshape(-1, 2),
        human_goals=np.array(human_goals, dtype=float).reshape(-1, 2),
    )


def run(env, controller, obs):
    controller.reset(obs)
    done = False
    while not done:
        out = controller.act(obs)
        assert isinstance(out, ControlOutput) and out.accelerations.shape == (obs.n_robots, 2)
        obs, done, _ = env.step(out.accelerations)
    return env.trajectory()


def test_straight_reaches_and_stops_on_the_goal():
    # Robot 0 has 2 m to go, robot 1 ten; robot 0 keeps being controlled after it arrived.
    # Robot 0 by hand (b = 1 m/s^2, v' = sqrt(0.04 + 2 (d - 0.2 v)) - 0.2, capped at 1, a clipped to 2):
    #   step 1: v' = 1 -> a = 2.5 -> 2: v 0.8, y 0.16       step 2: a = 0.5: v 1, y 0.52
    #   steps 3, 4: v 1, y 0.92, 1.32                       step 5: d 0.68 -> v' 0.8: y 1.68
    #   step 6: d 0.32 -> v' 0.4: y 1.92                    step 7: d 0.08 -> v' 0: y 2.00, stopped
    env = CrowdEnv()
    obs = env.reset_layout(layout([[0, 0], [3, 0]], [[0, 2], [3, 10]]))
    traj = run(env, StraightController(), obs)
    y0 = traj.robot_positions[:, 0, 1]
    np.testing.assert_allclose(y0[:8], [0, 0.16, 0.52, 0.92, 1.32, 1.68, 1.92, 2.0], atol=1e-12)
    np.testing.assert_allclose(y0[8:], 2.0, atol=1e-12)  # parked on the goal
    np.testing.assert_allclose(traj.robot_velocities[7:, 0], 0.0, atol=1e-12)
    # Robot 0 is within 0.3 m of its goal at step 6 (y = 1.92). Robot 1 runs the same profile shifted by 8 m:
    # y = 9.68 at step 25 (0.32 m short), 9.92 at step 26 -> 10.4 s.
    m = episode_metrics(traj)
    assert m.success and m.reach_times == (2.4, 10.4) and m.travel_time == 10.4
    assert np.abs(traj.robot_velocities).max() <= 1.0 + 1e-12


def test_orca_controller_follows_orca_and_avoids_a_human():
    # A human walks south down the robot's lane (5 cm off it): ORCA robot and human pass each other.
    env = CrowdEnv()
    obs = env.reset_layout(layout([[0, -4]], [[0, 4]], [[0.05, 4]], [[0.05, -4]]))
    controller = OrcaController()
    v = controller.desired_velocities(obs)
    out = controller.act(obs)
    np.testing.assert_allclose(out.accelerations, np.clip(v / 0.4, -2, 2))
    traj = run(env, controller, obs)
    m = episode_metrics(traj)
    assert m.success and m.min_distance > 0.6
    assert np.abs(traj.robot_positions[:, 0, 0]).max() > 0.2  # it stepped aside


def test_straight_may_pass_the_goal_by_up_to_b_tau_squared_over_8_and_settles_back():
    # The braking rule keeps the continuous braking distance v'^2 / (2 b); stopping in whole 0.4 s steps goes
    # farther. Robot 0 heads for (7, 7) and keeps being controlled while robot 1 travels 20 m: it passes its
    # goal by 2 cm (b tau^2 / 8 = 1 x 0.16 / 8) along its way, then settles back within millimetres.
    env = CrowdEnv()
    obs = env.reset_layout(layout([[0, 0], [-3, 0]], [[7, 7], [-3, 20]]))
    traj = run(env, StraightController(), obs)
    past = (traj.robot_positions[:, 0] - [7.0, 7.0]) @ (np.array([1.0, 1.0]) / np.sqrt(2.0))
    assert 0.019 < past.max() <= 0.0201
    assert np.abs(traj.robot_positions[-1, 0] - [7.0, 7.0]).max() < 0.005
