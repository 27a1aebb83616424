"""CrowdEnv: robot dynamics and clipping, episode end, observations, reproducibility."""

import dataclasses

import numpy as np
import pytest

from crowdsim.baselines import StraightController
from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.metrics import episode_metrics
from crowdsim.profiles import PROFILES
from crowdsim.scenarios import Layout

V1 = PROFILES["v1"]


def one_robot(start=(0.0, 0.0), goal=(0.0, 9.0), humans=(), human_goals=()):
    return Layout(
        robot_starts=np.array([start], dtype=float),
        robot_goals=np.array([goal], dtype=float),
        human_starts=np.array(humans, dtype=float).reshape(-1, 2),
        human_goals=np.array(human_goals, dtype=float).reshape(-1, 2),
    )


def test_config_validation_names_the_value():
    with pytest.raises(SimulationError, match="dt.*-0.4"):
        EnvConfig(dt=-0.4)
    with pytest.raises(SimulationError, match="history_len.*0"):
        EnvConfig(history_len=0)
    with pytest.raises(SimulationError, match="crossing.*'square'"):
        EnvConfig(crossing="square")
    with pytest.raises(SimulationError, match="success_rule.*'any'"):
        EnvConfig(success_rule="any")
    with pytest.raises(SimulationError, match="timeout_margin.*2.0"):
        EnvConfig(time_limit=2.0, timeout_margin=2.0)
    with pytest.raises(SimulationError, match="spawn_separation.*-0.1"):
        EnvConfig(spawn_separation=-0.1)
    with pytest.raises(SimulationError, match="robots_visible.*'yes'"):
        EnvConfig(robots_visible="yes")


def test_max_steps_per_profile():
    # paper: steps start while t < 40 - 1 = 39 s, i.e. at t = 0, 0.4, ..., 38.8: 98 steps (39 / 0.4 = 97.5).
    assert EnvConfig().max_steps == 98
    # v1: 30 s at 0.4 s, no margin (30 / 0.4 = 75.00000000000001 in floats).
    assert V1.max_steps == 75
    # Margin 1 s of 2 s: steps start at t = 0, 0.4, 0.8 (1.2 >= 1): 3 steps.
    assert EnvConfig(time_limit=2.0).max_steps == 3
    # A margin 1e-11 s short of the limit: t = 0 still starts a step, and the env runs it; the rounding
    # tolerance alone made the count 0 (2.5e-11 steps less 1e-9).
    short = EnvConfig(timeout_margin=40.0 - 1e-11)
    assert short.max_steps == 1
    env = CrowdEnv(short)
    env.reset_layout(one_robot())
    obs, done, info = env.step(np.zeros((1, 2)))
    assert done and info["timeout"] and obs.step == short.max_steps


def test_no_step_ends_after_the_time_limit():
    """No margin and 10.1 s, not a whole number of 0.4 s steps: the 26th step would start at 10.0 s and end at
    10.4 s, where a lone robot 9.9 m from its goal arrives; it was run, and the episode was a success with a
    travel time of 10.4 s, past its 10.1 s time limit. Now the episode stops after 25 steps, at 10.0 s."""
    config = EnvConfig(time_limit=10.1, timeout_margin=0.0)
    assert config.max_steps == 25 and EnvConfig(time_limit=10.4, timeout_margin=0.0).max_steps == 26
    assert EnvConfig(dt=0.9, time_limit=1.0, timeout_margin=0.0).max_steps == 1
    env = CrowdEnv(config)
    obs, done, controller = env.reset(0, "circle", 0, 1), False, StraightController()
    while not done:
        obs, done, info = env.step(controller.act(obs).accelerations)
    m = episode_metrics(env.trajectory())
    assert obs.time <= config.time_limit and info["timeout"] and not m.success and np.isnan(m.travel_time)
    longer = CrowdEnv(EnvConfig(time_limit=10.4, timeout_margin=0.0))
    obs, done = longer.reset(0, "circle", 0, 1), False
    while not done:
        obs, done, info = longer.step(controller.act(obs).accelerations)
    assert info["success"] and episode_metrics(longer.trajectory()).travel_time == pytest.approx(10.4)


def test_paper_episode_times_out_after_98_steps_at_39_2_s():
    env = CrowdEnv()
    env.reset_layout(one_robot())
    done, steps = False, 0
    while not done:
        obs, done, info = env.step(np.zeros((1, 2)))
        steps += 1
    assert steps == 98 and obs.time == pytest.approx(39.2)
    assert info["timeout"] and not info["success"]


def test_double_integrator_and_clipping_rule():
    env = CrowdEnv()
    env.reset_layout(one_robot())
    # Step 1: a = (5, -5) is clipped to the acceleration bound (2, -2): v = (0.8, -0.8),
    # s = 0.5 * 0.4^2 * (2, -2) = (0.16, -0.16).
    obs, done, info = env.step(np.array([[5.0, -5.0]]))
    np.testing.assert_allclose(obs.robot_last_actions, [[2.0, -2.0]])
    np.testing.assert_allclose(obs.robot_velocities, [[0.8, -0.8]])
    np.testing.assert_allclose(obs.robot_positions, [[0.16, -0.16]])
    assert info["clipped"].tolist() == [True] and not done
    # Step 2: a_x = 5 would exceed v_max: clipped to (1 - 0.8) / 0.4 = 0.5; a_y = 0 is within
    # [max(-2, (-1 + 0.8) / 0.4), min(2, (1 + 0.8) / 0.4)] = [-0.5, 2] and stays 0.
    # x = 0.16 + 0.4 * 0.8 + 0.08 * 0.5 = 0.52; y = -0.16 - 0.32 = -0.48.
    obs, _, info = env.step(np.array([[5.0, 0.0]]))
    np.testing.assert_allclose(obs.robot_last_actions, [[0.5, 0.0]])
    np.testing.assert_allclose(obs.robot_velocities, [[1.0, -0.8]])
    np.testing.assert_allclose(obs.robot_positions, [[0.52, -0.48]])
    # Step 3: braking hard in y from -0.8: a_y = 2 (bound), v_y = 0; a_x = -0.5 is inside the bounds.
    obs, _, info = env.step(np.array([[-0.5, 3.0]]))
    np.testing.assert_allclose(obs.robot_last_actions, [[-0.5, 2.0]])
    np.testing.assert_allclose(obs.robot_velocities, [[0.8, 0.0]], atol=1e-15)
    assert info["clipped"].tolist() == [True]


def test_bad_actions_and_call_order_raise():
    env = CrowdEnv()
    with pytest.raises(SimulationError, match="before reset"):
        env.step(np.zeros((1, 2)))
    env.reset_layout(one_robot())
    with pytest.raises(SimulationError, match=r"\(1, 2\).*\(3,\)"):
        env.step(np.zeros(3))
    with pytest.raises(SimulationError, match="non-finite"):
        env.step(np.array([[np.nan, 0.0]]))
    # each was taken: "1" as 1.0, True as 1.0, 1+1j as 1.0 with only numpy's ComplexWarning
    for given, dtype in (
        (np.array([["1", "0"]]), "<U1"),
        (np.ones((1, 2), bool), "bool"),
        ([[1 + 1j, 0]], "complex128"),
    ):
        with pytest.raises(
            SimulationError,
            match=rf"^robot_accelerations must be a \(1, 2\) array of real numbers, got one of {dtype}$",
        ):
            env.step(given)
    env.step([[1, 0]])  # integers are numbers


def test_invalid_scenario_and_sizes_name_the_value():
    env = CrowdEnv()
    with pytest.raises(SimulationError, match="'square'"):
        env.reset(0, "square", 5)
    with pytest.raises(SimulationError, match="n_humans.*51"):
        env.reset(0, "circle", 51)
    with pytest.raises(SimulationError, match="n_robots.*13"):
        env.reset(0, "circle", 5, 13)
    with pytest.raises(SimulationError, match="seed.*-1"):
        env.reset(-1, "circle", 5)


def test_reaching_the_goal_ends_the_episode_and_is_latched():
    env = CrowdEnv()
    env.reset_layout(one_robot(goal=(0.0, 0.8)))
    # Full acceleration north: y = 0.16; then a is clipped to 0.5 by v_max: y = 0.16 + 0.32 + 0.04 = 0.52,
    # 0.28 m from the goal: reached at step 2.
    obs, done, _ = env.step(np.array([[0.0, 2.0]]))
    assert not done and not obs.robot_reached[0]
    obs, done, info = env.step(np.array([[0.0, 2.0]]))
    assert obs.robot_positions[0, 1] == pytest.approx(0.52)
    assert done and obs.robot_reached[0] and info["success"] and not info["timeout"]
    with pytest.raises(SimulationError, match="ended"):
        env.step(np.zeros((1, 2)))


def test_time_limit_ends_the_episode():
    env = CrowdEnv(dataclasses.replace(V1, time_limit=2.0))
    env.reset_layout(one_robot())
    for k in range(5):
        obs, done, info = env.step(np.zeros((1, 2)))
        assert done == (k == 4)
    assert info["timeout"] and not info["success"]
    assert obs.time == pytest.approx(2.0) and obs.step == 5
    assert env.trajectory().n_steps == 5


def test_observation_layout_and_history_padding():
    assert EnvConfig().history_len == 9  # the predictors' observed length, crowdsim.world.OBS_LEN
    env = CrowdEnv(EnvConfig(history_len=3))
    obs = env.reset(4, "circle", 5, 2)
    assert obs.robot_positions.shape == (2, 2) and obs.human_positions.shape == (5, 2)
    assert obs.history.shape == (3, 7, 2)
    start = np.concatenate([obs.robot_positions, obs.human_positions])
    np.testing.assert_array_equal(obs.history, np.broadcast_to(start, (3, 7, 2)))
    obs1, _, _ = env.step(np.zeros((2, 2)))
    obs2, _, _ = env.step(np.zeros((2, 2)))
    obs3, _, _ = env.step(np.zeros((2, 2)))
    np.testing.assert_array_equal(obs3.history[0, 2:], obs1.human_positions)  # robots first, then humans
    np.testing.assert_array_equal(obs3.history[-1, :2], obs3.robot_positions)
    np.testing.assert_array_equal(obs3.history[1, 2:], obs2.human_positions)
    assert obs3.radius == 0.3 and obs3.dt == 0.4


def test_humans_walk_by_orca_and_see_the_robots():
    # A human walking east towards a parked robot 4 m ahead (10 cm off its line) must step around it.
    env = CrowdEnv()
    env.reset_layout(
        one_robot(start=(0.0, 0.0), goal=(0.0, 9.0), humans=[(-4.0, 0.1)], human_goals=[(4.0, 0.1)])
    )
    obs, _, _ = env.step(np.zeros((1, 2)))
    # Within the 5 s horizon at 1 m/s it would hit the robot: it slows down at once (RVO2's cut-off case).
    assert np.linalg.norm(obs.human_velocities[0]) < 0.5
    lateral, closest = 0.0, np.inf
    for _ in range(20):
        obs, _, _ = env.step(np.zeros((1, 2)))
        lateral = max(lateral, abs(obs.human_positions[0, 1]))
        closest = min(closest, np.linalg.norm(obs.human_positions[0] - obs.robot_positions[0]))
    # The parked robot takes no share of the avoidance (its "reciprocal" half is never executed), so the
    # human can come slightly closer than ORCA's 0.62 m, but not into contact.
    assert lateral > 0.3 and closest > 0.6
    assert obs.human_positions[0, 0] > 3.0  # it went past


def test_same_seed_same_episode():
    def run(seed):
        env = CrowdEnv()
        obs = env.reset(seed, "perpendicular", 7, 3)
        done = False
        while not done:
            obs, done, _ = env.step(np.tile([0.0, 2.0], (3, 1)))
        return env.trajectory()

    a, b, c = run(11), run(11), run(12)
    for name in ("robot_positions", "human_positions", "human_velocities", "human_goals"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.human_goals, c.human_goals)


def test_crowd_without_robots_ends_when_every_human_arrived():
    env = CrowdEnv()
    env.reset(0, "circle", 5, 0)
    done, info = False, {}
    while not done:
        _, done, info = env.step(np.zeros((0, 2)))
    traj = env.trajectory()
    assert info["success"]
    assert np.all(np.linalg.norm(traj.human_positions[-1] - traj.human_goals, axis=1) < 0.3)
    assert traj.robot_positions.shape == (traj.n_steps + 1, 0, 2)


def test_simultaneous_success_waits_for_every_robot_inside_at_once():
    # Robot 0 starts on its goal and is pushed off east; robot 1 reaches its goal at step 2 (as above: y =
    # 0.52, 0.28 m from (5, 0.8)). Robot 0: x = 0.16 at step 1 (inside), 0.52 at step 2 (outside).
    layout = Layout(
        robot_starts=np.array([[0.0, 0.0], [5.0, 0.0]]),
        robot_goals=np.array([[0.0, 0.0], [5.0, 0.8]]),
        human_starts=np.zeros((0, 2)),
        human_goals=np.zeros((0, 2)),
    )
    push = np.array([[2.0, 0.0], [0.0, 2.0]])
    first = CrowdEnv(V1)
    first.reset_layout(layout)
    first.step(push)
    obs, done, info = first.step(push)
    assert obs.robot_positions[0, 0] == pytest.approx(0.52)
    assert done and info["success"]  # first_reach: robot 0 reached at step 0, robot 1 at step 2
    assert episode_metrics(first.trajectory()).travel_time == 0.8

    both = CrowdEnv()  # paper: simultaneous
    obs = both.reset_layout(layout)
    assert obs.robot_reached.tolist() == [True, False]
    both.step(push)
    obs, done, _ = both.step(push)
    assert not done and obs.robot_reached.tolist() == [True, True]  # reached at some point, not together
    controller = StraightController()
    for _ in range(40):
        obs, done, info = both.step(controller.act(obs).accelerations)
        if done:
            break
    assert done and info["success"]
    assert np.all(np.linalg.norm(obs.robot_positions - obs.robot_goals, axis=1) < 0.3)
    m = episode_metrics(both.trajectory())
    assert m.success and m.travel_time == pytest.approx(obs.time) and m.reach_times == (0.0, 0.8)
    assert both.trajectory().success_rule == "simultaneous"


# v1 episodes recorded with the simulator before the profiles existed (StraightController, 6 humans, 3
# robots): the v1 profile must reproduce them bit for bit.
V1_EPISODES = {
    ("circle", 3): (
        0.4770132844111444,
        [
            [-0.027749566226718994, 6.118599098629747],
            [1.538668001339696, -0.10899663214631745],
            [2.9423847930093583, -1.3548407778469236],
            [0.7802779978740197, 2.924100422339943],
            [-2.2444712772578637, 2.450691950218957],
            [0.4734884325320734, 5.689706872496366],
        ],
    ),
    ("perpendicular", 5): (
        0.6305523189528461,
        [
            [4.279378559321248, 2.6469137713282684],
            [-3.874489932546199, -0.26115352992046703],
            [5.266088225568255, -2.282123354652665],
            [4.726295152769794, -1.529032864288608],
            [3.657898289901178, -2.112307598202763],
            [4.668479609522392, -5.278747824555177],
        ],
    ),
}


@pytest.mark.parametrize("scenario, seed", list(V1_EPISODES))
def test_v1_profile_reproduces_the_first_simulator(scenario, seed):
    env = CrowdEnv(V1)
    obs = env.reset(seed, scenario, 6, 3)
    controller = StraightController()
    done, info = False, {}
    while not done:
        obs, done, info = env.step(controller.act(obs).accelerations)
    traj = env.trajectory()
    m = episode_metrics(traj)
    min_distance, final_humans = V1_EPISODES[scenario, seed]
    assert traj.n_steps == 26 and info["success"] and m.reach_times == (10.4, 10.4, 10.4)
    assert m.min_distance == min_distance
    np.testing.assert_array_equal(traj.human_positions[-1], final_humans)


def test_profile_reaches_the_layout():
    paper = CrowdEnv().reset(0, "perpendicular", 5)
    v1 = CrowdEnv(V1).reset(0, "perpendicular", 5)
    assert np.all(np.abs(paper.human_positions[:, 0]) >= 5.0)  # the fork's U(1.0, 1.2) * 5
    assert not np.array_equal(paper.human_positions, v1.human_positions)


def test_changing_the_steps_info_in_place_leaves_the_trajectory_as_it_was():
    """info["accelerations"] was the array the trajectory records: a caller scaling it in place rewrote
    trajectory().robot_accelerations (a record of accelerations never applied)."""
    env = CrowdEnv()
    env.reset(0, "circle", 2, 3)
    _, _, info = env.step(np.ones((3, 2)))
    info["accelerations"] *= 0.0
    np.testing.assert_array_equal(env.trajectory().robot_accelerations[0], np.ones((3, 2)))
    np.testing.assert_array_equal(env.step(np.ones((3, 2)))[0].robot_last_actions, np.ones((3, 2)))
