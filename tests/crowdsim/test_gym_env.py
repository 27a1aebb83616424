"""crowdmpc/CrowdNav-v0: gymnasium's checker, the observation layout, the reward by hand, the episode is
CrowdEnv's, the time limit, rendering, and the velocity wrapper."""

import dataclasses
import math
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import crowdsim
from crowdsim.baselines import OrcaController, StraightController
from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from crowdsim.errors import LayoutWarning, SimulationError
from crowdsim.gym_env import (
    COLUMNS,
    GOAL,
    POSITION,
    PRESENT,
    VELOCITY,
    ComparableObservation,
    CrowdNavEnv,
    RewardConfig,
)
from crowdsim.gym_wrappers import VelocityControl
from crowdsim.metrics import episode_metrics
from crowdsim.orca import OrcaParams
from crowdsim.profiles import make_env_config
from crowdsim.scenarios import Layout
from tests.same_metrics import same_metrics

WRAPPED = "is different from the unwrapped version"  # check_env's note on any wrapper, not a failure


def checked(env: gym.Env, expected: tuple[str, ...] = ()) -> None:
    """check_env passes, and warns of nothing but ``expected``."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    unexpected = [str(w.message) for w in caught if not any(e in str(w.message) for e in expected)]
    assert not unexpected


def one_robot(human: tuple[float, float]) -> Layout:
    """A robot at rest at the origin (goal 5 m south) and a human standing at ``human`` (its own goal)."""
    point = np.array([human])
    return Layout(np.zeros((1, 2)), np.array([[0.0, -5.0]]), point, point)


# --------------------------------------------------------------------------------------------- the API
def test_importing_crowdsim_registers_the_environment_by_its_path():
    spec = gym.spec(crowdsim.ENV_ID)
    assert crowdsim.ENV_ID == "crowdmpc/CrowdNav-v0"
    assert spec.entry_point == "crowdsim.gym_env:CrowdNavEnv"


def test_importing_crowdsim_loads_neither_the_simulator_nor_matplotlib():
    script = (
        "import sys, crowdsim; print(sorted(m for m in ('crowdsim.env', 'matplotlib') if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout == "[]\n", done.stderr


@pytest.mark.parametrize(
    "kwargs", [{"render_mode": "rgb_array"}, {"n_humans": 3, "max_humans": 6, "n_robots": 2, "max_robots": 4}]
)
def test_check_env_passes_without_a_warning(kwargs):
    checked(gym.make(crowdsim.ENV_ID, **kwargs).unwrapped)


def test_check_env_passes_the_velocity_wrapper():
    checked(VelocityControl(gym.make(crowdsim.ENV_ID, render_mode="rgb_array")), expected=(WRAPPED,))
    checked(VelocityControl(gym.make(crowdsim.ENV_ID, n_humans=2).unwrapped, gain=1.0), expected=(WRAPPED,))


def test_the_spaces():
    env = CrowdNavEnv(n_humans=5, n_robots=3)
    assert env.action_space == gym.spaces.Box(-2.0, 2.0, (3, 2), dtype=np.float64)  # a_max, Table I
    assert env.observation_space.shape == (8, len(COLUMNS)) and env.observation_space.dtype == np.float64
    # 2 x 10 m square + 1 m/s x 40 s; velocities within v_max = v_pref = 1 m/s
    assert env.observation_space.high[0].tolist() == [60, 60, 1, 1, 60, 60, 1]
    assert env.observation_space.low[0].tolist() == [-60, -60, -1, -1, -60, -60, 0]
    assert VelocityControl(env).action_space == gym.spaces.Box(-1.0, 1.0, (3, 2), dtype=np.float64)


def test_observation_rows_are_the_agents_robots_first_then_padding():
    env = CrowdNavEnv(n_humans=2, max_humans=4, n_robots=2, max_robots=3)
    obs, info = env.reset(seed=5)
    native = info["observation"]
    assert obs.shape == (7, 7) and info["seed"] == 5 and info["n_humans"] == 2
    robots, humans = obs[:3], obs[3:]
    np.testing.assert_array_equal(robots[:2, POSITION], native.robot_positions)
    np.testing.assert_array_equal(robots[:2, VELOCITY], native.robot_velocities)
    np.testing.assert_array_equal(robots[:2, GOAL], native.robot_goals)
    np.testing.assert_array_equal(humans[:2, POSITION], native.human_positions)
    assert (humans[:, GOAL] == 0).all()  # unobserved, as in CrowdNav
    assert robots[:2, PRESENT].tolist() == [1, 1] and humans[:2, PRESENT].tolist() == [1, 1]
    assert not robots[2].any() and not humans[2:].any()  # padding
    obs, info = env.reset(seed=5, options={"n_humans": 4, "n_robots": 3, "scenario": "perpendicular"})
    assert obs[:, PRESENT].all() and info["scenario"] == "perpendicular"


def test_the_layout_seed_is_the_simulators():
    env = CrowdNavEnv(n_humans=4)
    _, info = env.reset(seed=11)
    native = CrowdEnv(EnvConfig()).reset(11, "circle", 4, 3)
    assert info["observation"] == native  # ComparableObservation: field by field, arrays exactly
    assert isinstance(info["observation"], ComparableObservation)
    _, first = env.reset()  # unseeded resets draw from the generator reset(seed=11) seeded
    env.reset(seed=11)
    _, again = env.reset()
    assert first["seed"] == again["seed"] and first["observation"] == again["observation"]


def test_a_layout_episode_has_no_seed_and_keeps_the_generators_sequence():
    env = CrowdNavEnv(n_robots=1, n_humans=1, render_mode="rgb_array")
    env.reset(seed=3)
    _, plain = env.reset()
    env.reset(seed=3)
    _, info = env.reset(options={"layout": one_robot((0.0, 2.0))})
    assert info["seed"] is None and env.episode["seed"] is None and info["scenario"] == "layout"
    env.step(np.zeros((1, 2)))
    assert env.render().shape == (480, 640, 3)  # titled without a seed
    _, after = env.reset()  # the layout's reset took its draw: the next episode is the same as without it
    env.reset(seed=3)
    env.reset()
    _, again = env.reset()
    assert after["seed"] == again["seed"] != plain["seed"]
    _, seeded = env.reset(seed=8, options={"layout": one_robot((0.0, 2.0))})
    assert seeded["seed"] is None  # seed 8 seeded the generator, not this layout


# numpy's ragged-array text ("setting an array element with a sequence. The requested array has an
# inhomogeneous shape after 1 dimensions...") named no row and ran on for two sentences
UNEQUAL = (
    "layout.human_starts must be a (N, 2) array of numbers: its rows are of unequal lengths, or one nests"
)


@pytest.mark.parametrize(
    "options, message",
    [
        (
            {"n_humans": 6},
            "options: n_humans=6 exceeds this environment's max_humans=5; make it with max_humans=6",
        ),
        ({"n_robots": 0}, "options: n_robots must be in [1, max_robots=3], got 0"),
        ({"n_robots": 4}, "options: n_robots must be in [1, max_robots=3], got 4; make it with max_robots=4"),
        (
            {"layout": Layout(np.zeros((4, 2)), np.ones((4, 2)), np.zeros((0, 2)), np.zeros((0, 2)))},
            "options: the layout's robots must be in [1, max_robots=3], got 4; make it with max_robots=4",
        ),
        ({"humans": 3}, "unknown reset options ['humans']; choose from"),
        ({"scenario": "square"}, "unknown scenario 'square'"),
        (
            {"layout": one_robot((0.0, 2.0)), "n_humans": 1},
            "reset option 'layout' sets the agents; drop ['n_humans']",
        ),
        ({"layout": one_robot((0.0, 99.0))}, "options['layout']: starts and goals must lie within ±20 m"),
        # the layout's own check comes before the bounds: these were numpy's ValueError, and a None field
        # read as out of bounds
        (
            {"layout": dataclasses.replace(one_robot((3.0, 0.0)), human_starts=[[3.0, 0.0], [1.0]])},
            UNEQUAL,
        ),
        (
            {"layout": dataclasses.replace(one_robot((3.0, 0.0)), human_starts=[[3.0, [0.0, 1.0]]])},
            UNEQUAL,
        ),
        (
            {"layout": dataclasses.replace(one_robot((3.0, 0.0)), human_starts=[["a", "b"]])},
            "layout.human_starts must be a (N, 2) array of numbers: could not convert string to float",
        ),
        (
            {"layout": dataclasses.replace(one_robot((3.0, 0.0)), human_goals=None)},
            "layout.human_goals must be a (N, 2) array, got shape ()",
        ),
    ],
)
def test_bad_reset_options_are_one_line(options, message):
    with pytest.raises(SimulationError) as exc:
        CrowdNavEnv().reset(seed=0, options=options)
    assert str(exc.value).startswith(message) and "\n" not in str(exc.value)


def test_a_bad_first_layout_leaves_the_env_usable():
    """gym.make's env after a first reset that raised: gymnasium's passive checker (gymnasium 1.4) then held
    None and every later step raised "cannot unpack non-iterable NoneType object", whatever the next layout;
    the environment is registered without it (crowdsim/__init__.py), and asking for it still works."""
    good = one_robot((3.0, 0.0))
    bad = dataclasses.replace(good, robot_starts=[[0.0, 0.0, 0.0]])
    env = gym.make(crowdsim.ENV_ID, n_humans=1, n_robots=1)
    with pytest.raises(SimulationError, match="layout.robot_starts"):
        env.reset(seed=0, options={"layout": bad})
    env.reset(seed=0, options={"layout": good})
    env.step(np.zeros(env.action_space.shape))
    checked = gym.make(crowdsim.ENV_ID, n_humans=1, n_robots=1, disable_env_checker=False)
    assert "PassiveEnvChecker" in str(checked)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"render_mode": "human"}, "render_mode must be None or 'rgb_array', got 'human'"),
        ({"n_robots": 0}, "n_robots must be an int in [1, 12], got 0"),
        ({"n_humans": 5, "max_humans": 4}, "max_humans must be an int in [5, 50], got 4"),
        ({"config": "paper"}, "config must be an EnvConfig or a mapping of its fields, got 'paper'"),
        (
            {"config": {"profile": "v1", "horizon": 2}},
            "config has no field 'horizon'; expected profile, visi",
        ),
        ({"config": {"orca": {"horizon": 2}}}, "config orca has no field 'horizon'; expected neighbor_dist,"),
        # plain data gives no OrcaParams: the refusal names the mapping it can give
        ({"config": {"orca": 2.0}}, "config orca must be a mapping of OrcaParams' fields (neighbor_dist, "),
        ({"config": {"visibility": "visible", "robots_visible": True}}, "config gives both visibility and"),
        ({"config": {"profile": "v2"}}, "unknown profile 'v2'; choose from ['paper', 'v1']"),
        ({"reward": {"sucess": 2}}, "reward has no field 'sucess'; expected success, collision, discomfort_"),
        ({"reward": 1.0}, "reward must be a RewardConfig or a mapping of its fields, got 1.0"),
        ({"reward": RewardConfig(), "end_on_collision": 1}, "end_on_collision must be a bool, got 1"),
    ],
)
def test_bad_constructor_arguments_are_one_line(kwargs, message):
    with pytest.raises(SimulationError, match=message.replace("[", r"\[").replace("(", r"\(")):
        CrowdNavEnv(**kwargs)


def test_bad_actions_and_calls_out_of_order_are_refused():
    env = CrowdNavEnv(n_humans=1, config=EnvConfig(time_limit=0.8, timeout_margin=0.0))
    with pytest.raises(SimulationError, match="before reset"):
        env.step(np.zeros((3, 2)))
    env.reset(seed=0)
    with pytest.raises(SimulationError, match=r"action must be a \(3, 2\) array, got shape \(2, 2\)"):
        env.step(np.zeros((2, 2)))
    with pytest.raises(SimulationError, match="1 non-finite"):
        env.step(np.array([[np.nan, 0.0], [0.0, 0.0], [0.0, 0.0]]))
    env.step(np.zeros((3, 2)))
    *_, truncated, _ = env.step(np.zeros((3, 2)))
    assert truncated
    with pytest.raises(SimulationError, match="after the episode ended"):
        env.step(np.zeros((3, 2)))


# ------------------------------------------------------------------------------------------- the reward
def test_the_reward_rules_in_their_order():
    rule = RewardConfig().step_reward
    # contact on the step that succeeds: the fork goes on after a contact, so success is paid too
    assert rule(-0.1, success=True, dt=0.4) == 0.75
    # ... unless the contact ends the episode (upstream CrowdNav): contact first, success not paid
    assert rule(-0.1, success=True, dt=0.4, contact_ends=True) == -0.25
    assert rule(-0.1, success=False, dt=0.4) == -0.25
    assert rule(0.1, success=True, dt=0.4) == 1.0
    assert rule(0.2, success=False, dt=0.4) == pytest.approx((0.2 - 0.4) * 0.5 * 0.4)
    assert rule(0.4, success=False, dt=0.4) == 0.0  # the discomfort distance itself
    with pytest.raises(SimulationError, match="RewardConfig.collision must be a finite number, got nan"):
        RewardConfig(collision=float("nan"))


def test_standing_0_3_m_from_a_human_costs_the_discomfort_penalty():
    env = CrowdNavEnv(n_robots=1, n_humans=1)
    obs, info = env.reset(seed=0, options={"layout": one_robot((0.0, 0.9))})
    assert info["scenario"] == "layout" and obs[1, POSITION].tolist() == [0.0, 0.9]
    _, reward, terminated, truncated, info = env.step(np.zeros((1, 2)))
    # nobody moves (the human is at its goal); boundaries 0.9 - 2 x 0.3 = 0.3 m apart
    assert info["surface_distance"] == pytest.approx([0.3])
    assert reward == pytest.approx((0.3 - 0.4) * 0.5 * 0.4) and info["robot_rewards"] == pytest.approx(
        [reward]
    )
    assert info["min_distance"] == pytest.approx(0.9) and not info["collision"] and not info["contact"]
    assert not (terminated or truncated)


@pytest.mark.parametrize("end_on_collision", [False, True])
def test_contact_costs_the_collision_penalty_and_may_end_the_episode(end_on_collision):
    env = CrowdNavEnv(n_robots=1, n_humans=1, end_on_collision=end_on_collision)
    with pytest.warns(LayoutWarning, match="0.5 m apart"):  # overlapping by 0.1 m, on purpose
        env.reset(seed=0, options={"layout": one_robot((0.0, 0.5))})
    _, reward, terminated, truncated, info = env.step(np.zeros((1, 2)))
    assert info["surface_distance"] == pytest.approx([-0.1])  # at the start of the step
    assert reward == -0.25 and terminated == end_on_collision and not truncated
    assert ("episode_metrics" in info) == end_on_collision


def _at_goal_beside_a_human() -> Layout:
    """A robot at rest 0.1 m from its goal (inside its 0.3 m radius: it succeeds on the first step), a
    human standing 0.5 m from it: boundaries overlapping by 0.1 m."""
    return Layout(np.zeros((1, 2)), np.array([[0.0, -0.1]]), np.array([[0.5, 0.0]]), np.array([[0.5, 0.0]]))


@pytest.mark.parametrize("end_on_collision, expected", [(False, -0.25 + 1.0), (True, -0.25)])
def test_contact_and_success_on_the_same_step(end_on_collision, expected):
    # With end_on_collision the contact comes first (upstream's Collision): no success, reported or paid,
    # and the episode's metrics say so too (timeout, no travel time), though the robot is at its goal.
    env = CrowdNavEnv(n_robots=1, n_humans=1, end_on_collision=end_on_collision)
    with pytest.warns(LayoutWarning, match="in contact from the first step"):  # on purpose
        env.reset(seed=0, options={"layout": _at_goal_beside_a_human()})
    _, reward, terminated, truncated, info = env.step(np.zeros((1, 2)))
    assert info["surface_distance"] == pytest.approx([-0.1]) and info["reached"].tolist() == [True]
    assert info["success"] != end_on_collision and not info["timeout"]
    assert reward == expected and info["robot_rewards"].tolist() == [expected]
    assert terminated and not truncated
    metrics = info["episode_metrics"]
    assert metrics.contact and metrics.contact_between_steps and metrics.reach_times == (0.0,)
    assert (metrics.success, metrics.timeout) == (not end_on_collision, end_on_collision)
    assert math.isnan(metrics.travel_time) == end_on_collision
    # What the closed loop reports (crowdsim.metrics of the trajectory) is unchanged: it has no contact rule.
    assert episode_metrics(env.simulator.trajectory()).success


def test_a_contact_that_ends_the_episode_pays_no_robot_the_success():
    # Two robots at their goals, only the first beside a human: the team's episode ends in collision, so the
    # second robot, 5 m from anyone, earns 0 (rule 4), not the success the team did not reach.
    env = CrowdNavEnv(n_robots=2, n_humans=1, end_on_collision=True)
    layout = Layout(
        np.array([[0.0, 0.0], [5.0, 0.0]]),
        np.array([[0.0, -0.1], [5.0, -0.1]]),
        np.array([[0.5, 0.0]]),
        np.array([[0.5, 0.0]]),
    )
    with pytest.warns(LayoutWarning, match="in contact from the first step"):  # on purpose
        env.reset(seed=0, options={"layout": layout})
    _, reward, terminated, _, info = env.step(np.zeros((2, 2)))
    assert terminated and not info["success"] and info["reached"].tolist() == [True, True]
    assert reward == -0.25 and info["robot_rewards"].tolist() == [-0.25, 0.0]


def _crossing() -> Layout:
    """Robot from 0 to (15, 0); a human from (4.12, 0.5) west to (-15, 0.5) at 1 m/s (0.4 m a step).
    Driven by StraightController the robot is at x = 0.16, 0.52, then 0.4 m a step further (1 m/s from the
    second step): x_k = 0.4 k - 0.28, the human at 4.12 - 0.4 k. Relative x after steps 5 and 6: 0.4 and
    -0.4; at 0.5 m apart in y, sqrt(0.16 + 0.25) = 0.640 m at both states (no contact: not < 0.6 m), 0.5 m
    halfway through step 6 (contact, boundaries -0.1 m apart)."""
    return Layout(
        np.zeros((1, 2)), np.array([[15.0, 0.0]]), np.array([[4.12, 0.5]]), np.array([[-15.0, 0.5]])
    )


@pytest.mark.parametrize("end_on_collision", [False, True])
def test_a_contact_between_two_steps_is_reported_as_it_ends_the_episode(end_on_collision):
    # robots invisible: the human's ORCA walks straight on
    config = EnvConfig(robots_visible=False)
    env = CrowdNavEnv(n_robots=1, n_humans=1, config=config, end_on_collision=end_on_collision)
    _, info = env.reset(options={"layout": _crossing()})
    robot = StraightController()
    steps = []
    for _ in range(6):
        steps.append(env.step(robot.act(info["observation"]).accelerations))
        info = steps[-1][4]
    assert [s[4]["contact_between_steps"] for s in steps] == [False] * 5 + [True]
    _, reward, terminated, truncated, info = steps[-1]
    assert info["observation"].robot_positions == pytest.approx(np.array([[2.12, 0.0]]))
    assert info["observation"].human_positions == pytest.approx(np.array([[1.72, 0.5]]))
    assert info["min_distance"] == pytest.approx(math.sqrt(0.41)) and not info["contact"]
    assert info["min_distance_between_steps"] == pytest.approx(0.5) and info["collision_between_steps"]
    assert info["surface_distance"] == pytest.approx([-0.1]) and reward == -0.25
    assert terminated == end_on_collision and not truncated
    if end_on_collision:
        m = info["episode_metrics"]
        assert (m.contact, m.collision, m.timeout, m.success) == (False, True, True, False)  # step-sampled
        assert m.contact_between_steps and m.min_distance_between_steps == pytest.approx(0.5)
        assert m.min_distance == pytest.approx(math.sqrt(0.41)) and m.n_steps == 6


def test_two_robots_crossing_within_a_step_touch_between_steps_in_the_info_not_in_the_reward():
    # _crossing's geometry with a second robot for the human: robot 1 from (3.84, 0.5) west at the same
    # speed, x = 4.12 - 0.4 k; relative x after steps 5 and 6 is 0.4 and -0.4 (0.640 m apart at both states),
    # 0.5 m halfway through step 6. The one human stands 10 m away.
    layout = Layout(
        np.array([[0.0, 0.0], [3.84, 0.5]]),
        np.array([[15.0, 0.0], [-15.0, 0.5]]),
        np.array([[0.0, 10.0]]),
        np.array([[0.0, 10.0]]),
    )
    env = CrowdNavEnv(n_robots=2, n_humans=1)
    _, info = env.reset(options={"layout": layout})
    robot = StraightController()
    steps = []
    for _ in range(7):
        steps.append(env.step(robot.act(info["observation"]).accelerations))
        info = steps[-1][4]
    assert [s[4]["robot_contact_between_steps"] for s in steps] == [False] * 5 + [True, False]
    assert not any(s[4]["robot_contact"] for s in steps) and [s[1] for s in steps] == [0.0] * 7
    five, six, seven = (s[4] for s in steps[4:])
    assert five["min_distance_robots"] == pytest.approx(math.sqrt(0.41)) == six["min_distance_robots"]
    assert six["min_distance_robots_between_steps"] == pytest.approx(0.5)
    assert seven["min_distance_robots_between_steps"] == pytest.approx(math.sqrt(0.41))  # its start


def test_the_time_limit_truncates_with_the_episode_metrics():
    config = EnvConfig(time_limit=2.0, timeout_margin=0.0)  # 5 steps of 0.4 s
    env = CrowdNavEnv(n_humans=2, config=config)
    env.reset(seed=3)
    steps = [env.step(np.zeros((3, 2))) for _ in range(5)]
    assert [s[2:4] for s in steps] == [(False, False)] * 4 + [(False, True)]
    _, reward, _, _, info = steps[-1]
    assert reward == 0.0 and info["timeout"] and not info["success"]
    assert same_metrics(info["episode_metrics"], episode_metrics(env.simulator.trajectory()))
    assert info["episode_metrics"].n_steps == 5 and info["episode_metrics"].timeout
    assert all("episode_metrics" not in s[4] for s in steps[:-1])


def test_the_position_bounds_take_the_time_limit_the_steps_end_by():
    """No margin and 1.0 / 0.9 not whole: a second step would run to 1.8 s, past the 1 s limit, and is not run
    (EnvConfig.max_steps). The bounds take 1 s of travel, 20 + 100 x 1 = 120 m, and hold the one step's."""
    config = EnvConfig(dt=0.9, time_limit=1.0, timeout_margin=0.0, v_max=100.0, a_max=1000.0)
    env = CrowdNavEnv(n_humans=1, config=config)
    assert config.max_steps == 1 and env.position_limit == pytest.approx(20.0 + 100.0 * 1.0)
    env.reset(seed=0)
    obs, _, terminated, truncated, info = env.step(np.tile([1000.0, 0.0], (3, 1)))
    np.testing.assert_array_equal(obs[:3, POSITION], info["observation"].robot_positions)
    assert truncated and not terminated and env.observation_space.contains(obs)
    assert CrowdNavEnv().position_limit == 60.0  # 40 s, the paper's: its 98 steps of 0.4 s end before


@pytest.mark.parametrize("crossing", ["paper", "v1"])
def test_the_scene_limit_holds_the_start_noise_of_a_fast_crowd(crossing):
    """Circle starts carry noise of up to v_pref / 2 per coordinate: at 100 m/s, up to 55 m from the centre,
    past the 20 m of twice the scene, so the observation clipped them by up to 24 m. The limit is now
    10 + 100 / 2 = 60 m, and the observation is every start as it is; 20 m still at the paper's 1 m/s."""
    config = EnvConfig(v_pref=100.0, dt=0.1, time_limit=0.1, timeout_margin=0.0, crossing=crossing)
    env = CrowdNavEnv(n_humans=5, config=config)
    assert env.scene_limit == 60.0 and CrowdNavEnv().scene_limit == 20.0
    for seed in range(20):
        obs, info = env.reset(seed=seed)
        native = info["observation"]
        assert np.abs(native.human_positions).max() <= env.scene_limit
        np.testing.assert_array_equal(obs[env.max_robots :, POSITION], native.human_positions)


def test_an_episode_is_crowdenvs_and_its_metrics_are_the_simulators():
    """The straight-line baseline through the gymnasium API, with its accelerations and with its velocities
    through VelocityControl, drives exactly as through CrowdEnv."""
    baseline = StraightController()
    native = CrowdEnv(EnvConfig())
    obs, done = native.reset(7, "circle", 4, 3), False
    while not done:
        obs, done, _ = native.step(baseline.act(obs).accelerations)
    expected = native.trajectory()

    for wrapped in (False, True):
        env = CrowdNavEnv(n_humans=4)
        driven = VelocityControl(env) if wrapped else env
        _, info = driven.reset(seed=7)
        total, ended = 0.0, False
        while not ended:
            native_obs = info["observation"]
            action = (
                baseline.desired_velocities(native_obs) if wrapped else baseline.act(native_obs).accelerations
            )
            _, reward, terminated, truncated, info = driven.step(action)
            total, ended = total + reward, terminated or truncated
        traj = env.simulator.trajectory()
        np.testing.assert_array_equal(traj.robot_positions, expected.robot_positions)
        np.testing.assert_array_equal(traj.human_positions, expected.human_positions)
        assert info["episode_metrics"] == episode_metrics(expected)
        assert terminated and info["success"]
        # the blind baseline brushes a human on its last step: the collision penalty and the success
        assert reward == (-0.25 + 1.0 if info["contact_between_steps"] else 1.0)


def test_orca_robots_reach_their_goals_through_the_velocity_wrapper():
    env = VelocityControl(CrowdNavEnv(n_humans=5))
    robots = OrcaController()
    _, info = env.reset(seed=2)
    terminated = truncated = False
    while not (terminated or truncated):
        _, reward, terminated, truncated, info = env.step(robots.desired_velocities(info["observation"]))
    assert terminated and info["episode_metrics"].success and reward == 1.0  # the success reward


# ------------------------------------------------------------------------------------ velocity, render
def test_the_velocity_tracker_by_hand():
    env = VelocityControl(CrowdNavEnv(n_robots=1, n_humans=1))
    env.reset(seed=0, options={"layout": one_robot((3.0, 3.0))})
    _, _, _, _, info = env.step(np.array([[0.5, -1.0]]))
    # from rest: (0.5, -1.0) / 0.4 s = (1.25, -2.5) m/s^2, the second clipped to a_max = 2
    assert info["accelerations"].tolist() == [[1.25, -2.0]]
    assert info["observation"].robot_velocities == pytest.approx(np.array([[0.5, -0.8]]))
    gentle = VelocityControl(CrowdNavEnv(n_robots=1, n_humans=1), gain=1.0)
    gentle.reset(seed=0, options={"layout": one_robot((3.0, 3.0))})
    assert gentle.step(np.array([[0.5, -1.0]]))[4]["accelerations"].tolist() == [[0.5, -1.0]]
    with pytest.raises(SimulationError, match=r"gain must be a number in \(0, 1/dt = 2.5\] 1/s, got 3"):
        VelocityControl(CrowdNavEnv(), gain=3)
    with pytest.raises(SimulationError, match="VelocityControl wraps a CrowdNavEnv"):
        VelocityControl(gym.make("CartPole-v1"))


@pytest.mark.parametrize("bad", [math.inf, math.nan])
def test_a_non_finite_velocity_command_is_refused_as_such(bad):
    """inf was clipped to a_max and the robot accelerated at full; NaN was refused as accelerations, which
    the user never gave. Rows past the episode's robots are ignored, as the tracker ignores them."""
    env = VelocityControl(CrowdNavEnv(n_robots=2, n_humans=1))
    env.reset(seed=0, options={"n_robots": 1})
    with pytest.raises(SimulationError, match="velocity action must be finite for the episode's 1 robot, "):
        env.step(np.array([[bad, 0.0], [0.0, 0.0]]))
    env.step(np.array([[0.5, 0.0], [bad, bad]]))


def test_an_action_of_no_numbers_is_one_line_naming_it():
    """numpy's "could not convert string to float" named neither the action nor what it must be."""
    env = CrowdNavEnv(n_robots=1, n_humans=1)
    env.reset(seed=0)
    with pytest.raises(SimulationError, match=r"^action must be an array of numbers, got list"):
        env.step([["a", "b"]])
    velocity = VelocityControl(CrowdNavEnv(n_robots=1, n_humans=1))
    velocity.reset(seed=0)
    with pytest.raises(SimulationError, match=r"^velocity action must be an array of numbers, got dict"):
        velocity.step({"vx": 1.0})
    # complex numbers: numpy kept the real part, with a ComplexWarning only
    with pytest.raises(SimulationError, match=r"^action must be an array of real numbers, got complex ones"):
        env.step(np.array([[1j, 1j]]))


@pytest.mark.parametrize(
    ("given", "held"),
    [
        (np.full((1, 2), "0.5"), "<U3"),
        (np.ones((1, 2), dtype=bool), "bool"),
        (np.array([[0.5, True]], dtype=object), "bool"),
        (np.array([[0.5, "1"]], dtype=object), "str"),
    ],
)
def test_an_action_of_texts_or_booleans_is_refused_as_the_simulator_refuses_it(given, held):
    """numbers() took "0.5" as 0.5 and True as 1.0, so the environment drove robots with what CrowdEnv.step
    refuses ("robot_accelerations must be a (1, 2) array of real numbers, got one of bool")."""
    refusal = rf"action must be an array of real numbers, got one of {held}$"
    env = CrowdNavEnv(n_robots=1, n_humans=1)
    env.reset(seed=0)
    with pytest.raises(SimulationError, match=f"^{refusal}"):
        env.step(given)
    velocity = VelocityControl(CrowdNavEnv(n_robots=1, n_humans=1))
    velocity.reset(seed=0)
    with pytest.raises(SimulationError, match=f"^velocity {refusal}"):
        velocity.step(given)
    env.step(np.array([[1, 0]]))  # integers are numbers, and the episode goes on
    env.step(np.array([[0.5, 1]], dtype=object))


def test_render_draws_an_rgb_frame():
    env = CrowdNavEnv(n_humans=3, render_mode="rgb_array")
    with pytest.raises(SimulationError, match="before reset"):
        env.render()
    env.reset(seed=1)
    env.step(np.zeros((3, 2)))
    frame = env.render()
    assert frame.shape == (480, 640, 3) and frame.dtype == np.uint8 and frame.std() > 0
    assert CrowdNavEnv().render() is None  # no render mode, nothing drawn
    env.close()
    env.close()


@pytest.mark.parametrize("end_on_collision", [False, True])
def test_the_last_step_is_paid_by_the_rules_as_the_forks_call_before_its_timeout(end_on_collision):
    """A contact on the step that reaches the time limit paid 0, the fork's Timeout: the fork's Timeout comes
    on a further call (the first to start at time_limit - 1 s or later), whose motion its episode never
    records, and the call before it pays the contact (-0.25), ending the episode with end_on_collision
    (upstream's Collision). So does this environment's last step."""
    config = EnvConfig(time_limit=0.4, timeout_margin=0.0)  # one step
    env = CrowdNavEnv(n_robots=1, n_humans=1, config=config, end_on_collision=end_on_collision)
    with pytest.warns(LayoutWarning, match="0.5 m apart"):
        env.reset(seed=0, options={"layout": one_robot((0.0, 0.5))})
    _, reward, terminated, truncated, info = env.step(np.zeros((1, 2)))
    assert info["surface_distance"] == pytest.approx([-0.1]) and info["timeout"]
    assert (reward, terminated, truncated) == (-0.25, end_on_collision, not end_on_collision)
    assert info["robot_rewards"].tolist() == [-0.25]


def test_the_frames_title_gives_the_time_as_the_legend_does(monkeypatch):
    """A 0.25 s step's first frame was titled "t = 0.2 s" beside the legend's "snapshots: 0.25 s"."""
    import crowdsim.plotting

    titles = []
    monkeypatch.setattr(crowdsim.plotting, "render_frame", lambda traj, title, **kw: titles.append(title))
    env = CrowdNavEnv(n_humans=3, render_mode="rgb_array", config=EnvConfig(dt=0.25))
    env.reset(seed=1)
    for _ in range(3):
        env.step(np.zeros((3, 2)))
        env.render()
    assert [t.split(": ")[-1] for t in titles] == ["t = 0.25 s", "t = 0.5 s", "t = 0.75 s"]


@pytest.mark.parametrize("bad", [math.inf, math.nan])
def test_a_non_finite_action_is_refused_as_the_action(bad):
    """It was refused by the simulator as "robot_accelerations must be a finite (1, 2) array", a name the
    gym user never gave (the velocity wrapper names its action); rows past the episode's robots are
    ignored, as they always were."""
    env = CrowdNavEnv(n_robots=2, n_humans=1)
    env.reset(seed=0, options={"n_robots": 1})
    with pytest.raises(SimulationError) as refused:
        env.step(np.array([[bad, 0.0], [0.0, 0.0]]))
    assert str(refused.value) == "action must be finite for the episode's 1 robot, got 1 non-finite entry"
    env.step(np.array([[0.5, 0.0], [bad, bad]]))


def test_an_outer_time_limit_leaves_the_metrics_to_episode_metrics():
    """gym.make(..., max_episode_steps=K) truncates on a step whose info the environment could not know to
    be the last, so it has no "episode_metrics"; env.unwrapped.episode_metrics() gives them, as the
    environment's own last step does."""
    env = gym.make(crowdsim.ENV_ID, max_episode_steps=3)
    with pytest.raises(SimulationError, match="no episode before reset"):
        env.unwrapped.episode_metrics()
    env.reset(seed=0)
    for _ in range(3):
        *_, truncated, info = env.step(np.zeros(env.action_space.shape))
    assert truncated and "episode_metrics" not in info
    metrics = env.unwrapped.episode_metrics()
    assert not metrics.success and metrics.timeout
    own = CrowdNavEnv(config=EnvConfig(time_limit=1.2, timeout_margin=0.0))  # three steps of 0.4 s
    own.reset(seed=0)
    for _ in range(3):
        *_, truncated, info = own.step(np.zeros(own.action_space.shape))
    assert truncated and same_metrics(info["episode_metrics"], metrics)
    assert same_metrics(own.episode_metrics(), metrics)


def test_plain_data_is_the_config_the_profile_names_with_its_fields_replaced():
    """gym.make's keywords from a YAML or JSON file (RL Zoo's env_kwargs) are plain data: a mapping is the
    profile's EnvConfig (its conventions, not only its label) with the other keys replaced."""
    env = gym.make(
        crowdsim.ENV_ID, config={"profile": "v1", "visibility": "invisible", "orca": {"time_horizon": 2.0}}
    )
    expected = dataclasses.replace(
        make_env_config("v1", "invisible"), orca=dataclasses.replace(OrcaParams(), time_horizon=2.0)
    )
    assert env.unwrapped.config == expected and env.unwrapped.config.max_steps == 75
    assert CrowdNavEnv(config={"time_limit": 8.0}).config == EnvConfig(time_limit=8.0)
    assert CrowdNavEnv(reward={"success": 2.0}).reward_config == RewardConfig(success=2.0)


def test_a_reset_that_raises_leaves_no_episode_and_the_generator_as_it_was():
    """The last episode carried on after a reset that raised (its step accepted), and the failed reset had
    used a draw of the generator (or reseeded it), so the resets after it drew other episodes than an
    environment that never tried it."""
    make = lambda: gym.make(crowdsim.ENV_ID, n_humans=8, max_humans=16, config={"spawn_separation": 1.5})  # noqa: E731
    env = make()
    env.reset(seed=0)
    with pytest.raises(SimulationError, match="could not place human"):  # no room for 16
        env.reset(seed=1, options={"n_humans": 16})
    with pytest.raises(SimulationError, match=r"^step\(\) called before reset\(\) \(or after a reset that"):
        env.step(np.zeros((3, 2)))
    for failed in ({}, {"seed": 7}):
        tried, untried = make(), make()
        tried.reset(seed=3)
        untried.reset(seed=3)
        with pytest.raises(SimulationError):
            tried.reset(options={"n_humans": 16}, **failed)
        assert tried.reset()[1]["seed"] == untried.reset()[1]["seed"]


@pytest.mark.parametrize("seed", [True, False])
def test_a_bool_seed_is_refused_as_crowdenv_refuses_it(seed):
    """gymnasium takes a bool for an int, so reset(seed=True) ran seed 1 where CrowdEnv.reset(True, ...)
    is refused; both refuse it, through the wrappers too, and the refused reset draws nothing."""
    with pytest.raises(SimulationError, match=rf"^seed must be an int >= 0, got {seed}$"):
        CrowdEnv().reset(seed, "circle", 5)
    for env in (CrowdNavEnv(), gym.make(crowdsim.ENV_ID), VelocityControl(gym.make(crowdsim.ENV_ID))):
        untried = CrowdNavEnv()
        env.reset(seed=3)
        untried.reset(seed=3)
        with pytest.raises(SimulationError, match=rf"^seed must be an int >= 0 or None, got {seed}$"):
            env.reset(seed=seed)
        assert env.reset()[1]["seed"] == untried.reset()[1]["seed"]


def test_the_velocity_gain_takes_numpy_numbers():
    assert VelocityControl(gym.make(crowdsim.ENV_ID), gain=np.float32(1.0)).gain == 1.0


def test_a_policy_changing_the_infos_observation_in_place_changes_no_reward():
    """The info's native observation shared its arrays with the state the next step's reward and distances are
    computed from: a policy taking the humans relative to a robot in place changed the rewards, silently."""

    def rewards(relative: bool) -> list[tuple[float, float]]:
        env = CrowdNavEnv(n_humans=4)
        _, info = env.reset(seed=1)
        paid = []
        for _ in range(10):
            obs = info["observation"]
            if relative:  # in place: the humans relative to the first robot, as a policy's input
                obs.human_positions[:] -= obs.robot_positions[0]
            _, reward, _, _, info = env.step(np.ones((3, 2)))
            paid.append((reward, info["min_distance_between_steps"]))
        return paid

    assert rewards(relative=True) == rewards(relative=False)


def test_a_policy_changing_the_environments_observation_in_place_changes_no_reward():
    """``CrowdNavEnv.observation`` handed out the state the next step's reward and distances are computed
    from, where the info's observation was a copy: humans moved onto the first robot in place (a policy's
    relative frame) made a step of no contact pay the collision penalty."""

    def rewards(moved: bool) -> list[tuple[float, float]]:
        env = CrowdNavEnv(n_humans=4)
        env.reset(seed=1)
        paid = []
        for _ in range(10):
            obs = env.observation
            if moved:
                obs.human_positions[:] = obs.robot_positions[0]
                obs.robot_velocities[:] = 0.0
            _, reward, _, _, info = env.step(np.ones((3, 2)))
            paid.append((reward, info["min_distance_between_steps"]))
        return paid

    assert rewards(moved=True) == rewards(moved=False)
    velocity = VelocityControl(CrowdNavEnv(n_humans=2))  # tracks from its own copy, as before
    velocity.reset(seed=1)
    velocity.step(np.full((3, 2), 0.5))
    np.testing.assert_allclose(velocity.unwrapped.observation.robot_velocities, 0.5)


def test_the_velocity_tracker_reads_the_environments_velocities_not_the_infos():
    """VelocityControl tracked the velocities of the info's observation, the very object the policy was
    handed: a policy zeroing them in place (a noisy reading dropped) had every command tracked from rest."""

    def positions(zeroed: bool) -> np.ndarray:
        env = VelocityControl(CrowdNavEnv(n_humans=2))
        _, info = env.reset(seed=1)
        seen = []
        for _ in range(6):
            if zeroed:
                info["observation"].robot_velocities[:] = 0.0
            obs, _, _, _, info = env.step(np.full((3, 2), 0.5))
            seen.append(obs)
        return np.array(seen)

    assert np.array_equal(positions(zeroed=True), positions(zeroed=False))


def test_end_on_collision_takes_numpys_bool_as_envconfigs_flags_do():
    """for end in np.array([False, True]) was refused, "must be a bool, got np.True_", where EnvConfig's
    robots_visible, the velocity gain and the sensor radius take numpy's scalars."""
    env = CrowdNavEnv(n_humans=1, end_on_collision=np.bool_(True))
    assert env.end_on_collision is True


@pytest.mark.parametrize(("profile", "steps"), [("paper", 98), ("v1", 75)])
def test_the_readmes_time_aware_limit_ends_with_the_environment(profile, steps):
    """README.md, "Seeds, ends, vectors", gave EnvConfig().max_steps (98) as the limit for every profile, but
    v1's crowd ends at 75 steps, where TimeAwareObservation then read 75/98, not 1."""
    readme = (Path(__file__).parents[2] / "README.md").read_text(encoding="utf-8")
    assert f"{steps} for " in " ".join(readme.split())
    made = gym.make(crowdsim.ENV_ID, config={"profile": profile})
    limit = made.unwrapped.config.max_steps
    assert limit == steps == make_env_config(profile).max_steps
    env = gym.wrappers.TimeAwareObservation(
        gym.make(crowdsim.ENV_ID, config={"profile": profile}, max_episode_steps=limit),
        flatten=False,
        normalize_time=True,
    )
    env.reset(seed=0)
    ended = False
    while not ended:
        obs, _, terminated, truncated, _ = env.step(np.zeros(env.action_space.shape))
        ended = terminated or truncated
    assert truncated and obs["time"] == pytest.approx(1.0)
