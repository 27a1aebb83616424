"""crowdmpc/CrowdNav-v0 among replayed crowds (crowdsim.replay, crowdsim.reaction): gymnasium's checker, a
person's row present only while tracked, the human rows' bounds from the recording by hand, the reward and
the info leaving untracked people out as the metrics do, and what a replay refuses."""

import math

import gymnasium as gym
import numpy as np
import pytest

import crowdsim
from crowdsim.env import Observation
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.gym_env import POSITION, PRESENT, VELOCITY, CrowdNavEnv
from crowdsim.gym_observation import human_limits
from crowdsim.gym_reward import state_info, step_closest
from crowdsim.metrics import episode_metrics
from crowdsim.replay import Recording
from crowdsim.scenarios import Layout
from tests.crowdsim.test_gym_env import checked
from tests.crowdsim.test_reaction import TIME_LIMIT
from tests.crowdsim.test_replay import four_people, walk

# four_people's 13 rows: two rows of history and an episode of 10 steps (4 s)
SHORT = {"history_len": 3, "time_limit": 4.0, "timeout_margin": 0.0}


def replay_env(crowd: str = "eth", **kwargs) -> CrowdNavEnv:
    config = EnvConfig(crowd=crowd, **SHORT)
    return CrowdNavEnv(config=config, recording=four_people(), scenario="perpendicular", n_humans=2, **kwargs)


@pytest.mark.parametrize("crowd", ["eth", "eth_reactive"])
def test_check_env_passes_a_replayed_crowd(crowd):
    config = EnvConfig(crowd=crowd, **SHORT)
    for render_mode in (None, "rgb_array"):
        made = gym.make(
            crowdsim.ENV_ID, config=config, recording=four_people(), n_humans=2, render_mode=render_mode
        )
        checked(made.unwrapped)


def test_a_persons_row_is_present_while_tracked_and_zeros_otherwise():
    env = replay_env()
    array, info = env.reset(seed=0)
    # A and B are tracked from the episode's third step: held where they begin, absent, so rows of zeros
    np.testing.assert_array_equal(info["observation"].human_present, [False, False])
    np.testing.assert_allclose(info["observation"].human_positions, [[-2.0, 1.0], [2.0, -1.0]])
    np.testing.assert_array_equal(array[3:], np.zeros((2, 7)))
    assert array[:3, PRESENT].tolist() == [1.0, 1.0, 1.0]
    for _ in range(3):
        array, *_ = env.step(np.zeros((3, 2)))
    np.testing.assert_allclose(array[3, POSITION], [-1.2, 1.0])  # four_people's own check, in the array
    np.testing.assert_allclose(array[3, VELOCITY], [1.0, 0.0], atol=1e-12)
    assert array[3:, PRESENT].tolist() == [1.0, 1.0]
    assert env.observation_space.contains(array)


def test_the_human_rows_are_bounded_by_the_recording():
    # four_people: centre (0, 0), farthest tracked (+-2.4, +-8), fastest step 0.4 m a row of 0.4 s
    far = math.hypot(2.4, 8.0)
    assert four_people().extent() == pytest.approx((far, 1.0))
    assert human_limits(four_people(), False, 4.0) == pytest.approx((far, 1.0))
    # reacting: at most 1 + CATCH_UP = 1.5 m/s, for 4 s, from a recorded position
    assert human_limits(four_people(), True, 4.0) == pytest.approx((far + 6.0, 1.5))
    for crowd, (position, speed) in (("eth", (far, 1.0)), ("eth_reactive", (far + 6.0, 1.5))):
        space = replay_env(crowd).observation_space
        # robots as in ORCA's crowd: 2 x 10 m square + 1 m/s x 4 s
        assert space.high[0].tolist() == [24.0, 24.0, 1.0, 1.0, 24.0, 24.0, 1.0]
        np.testing.assert_allclose(space.high[3], [position, position, speed, speed, 24.0, 24.0, 1.0])
        np.testing.assert_allclose(space.low[4], [-position, -position, -speed, -speed, -24.0, -24.0, 0.0])


def looking_on(present_before, present_after) -> tuple[Observation, Observation]:
    """One robot at the origin, at rest. Human 0 stands 0.3 m east of it, human 1 walks from 3 m north to
    2 m north (0.4 s) towards it at 2.5 m/s; which of them is tracked is given."""

    def obs(humans, velocities, present) -> Observation:
        return Observation(
            time=0.0, step=0, robot_positions=np.zeros((1, 2)), robot_velocities=np.zeros((1, 2)),
            robot_goals=np.array([[0.0, 5.0]]), robot_last_actions=np.zeros((1, 2)),
            robot_reached=np.array([False]), human_positions=np.array(humans, dtype=float),
            human_velocities=np.array(velocities, dtype=float), human_goals=np.zeros((2, 2)),
            history=np.zeros((1, 3, 2)), radius=0.3, dt=0.4,
            human_present=None if present is None else np.array(present, dtype=bool),
        )  # fmt: skip

    velocities = [[0.0, 0.0], [0.0, -2.5]]
    return (
        obs([[0.3, 0.0], [0.0, 3.0]], velocities, present_before),
        obs([[0.3, 0.0], [0.0, 2.0]], velocities, present_after),
    )


def test_the_step_figures_leave_out_people_not_tracked():
    before, after = looking_on(None, None)  # ORCA's crowd: everyone
    np.testing.assert_allclose(step_closest(before, after), [[0.3, 2.0]])
    everyone = state_info(after, 0.3)
    assert everyone["min_distance"] == pytest.approx(0.3) and everyone["contact"] and everyone["collision"]
    # human 1's projected path (2.5 m/s x 1.2 s = 3 m south from 2 m north) runs through the robot
    assert everyone["discomfort"]
    # human 0 was not tracked at the step's start: it counts at the new state, not over the step
    before, after = looking_on([False, True], [True, True])
    np.testing.assert_allclose(step_closest(before, after), [[math.inf, 2.0]])
    assert state_info(after, 0.3)["min_distance"] == pytest.approx(0.3)
    # human 0 not tracked now: its 0.3 m is nobody's; human 1, 2 m off, still walks at the robot
    before, after = looking_on([True, True], [False, True])
    assert state_info(after, 0.3) == {
        "min_distance": 2.0,
        "collision": False,
        "contact": False,
        "discomfort": True,
    }
    # nobody tracked: no distance at all, and no discomfort
    before, after = looking_on([False, False], [False, False])
    assert np.isinf(step_closest(before, after)).all()
    assert state_info(after, 0.3) == {
        "min_distance": math.inf,
        "collision": False,
        "contact": False,
        "discomfort": False,
    }


@pytest.mark.parametrize("crowd", ["eth", "eth_reactive"])
def test_the_infos_figures_are_the_episodes_metrics(crowd):
    """Driven up the y axis through the crossing people and past one who stands on their path before being
    tracked there, the robots' step-by-step info gives the episode's metrics (which count a person only while
    tracked): the smallest distances, the states in contact."""
    config = EnvConfig(crowd=crowd, time_limit=TIME_LIMIT, history_len=3)
    # pair_and_crosser's people, and a fourth tracked on rows 40-42 at (0, 2): held there before, on the path
    rows = walk(1, range(47), -9.2, 0.4, 0.2) + walk(2, range(47), -9.2, 0.4, -0.2)
    rows += walk(3, range(5, 31), 6.0, -0.4, 3.0) + walk(4, range(40, 43), 0.0, 0.0, 2.0)
    recording = Recording.from_rows("eth", np.array(rows), frame_step=6)
    env = CrowdNavEnv(config=config, recording=recording, scenario="perpendicular", n_humans=4)
    _, info = env.reset(seed=0)
    infos = [state_info(info["observation"], 0.3)]
    swept, done = [], False
    while not done:
        _, _, terminated, truncated, step = env.step(np.tile([0.0, 0.5], (3, 1)))
        infos.append(step)
        swept.append(step["min_distance_between_steps"])
        done = terminated or truncated
    metrics = step["episode_metrics"]
    assert metrics == episode_metrics(env.simulator.trajectory())
    assert min(i["min_distance"] for i in infos) == metrics.min_distance
    assert min(swept) == pytest.approx(metrics.min_distance_between_steps, abs=1e-12)
    assert sum(i["contact"] for i in infos) == metrics.contact_steps
    assert sum(i["collision"] for i in infos) == metrics.collision_steps
    assert sum(i["discomfort"] for i in infos) == metrics.discomfort_steps
    assert metrics.collision  # the robots met the people: the test looks at something


def test_a_replay_refuses_a_layout_without_drawing_and_needs_its_recording():
    env, fresh = replay_env(), replay_env()
    env.reset(seed=1)
    fresh.reset(seed=1)
    layout = Layout(np.zeros((1, 2)), np.ones((1, 2)), np.zeros((0, 2)), np.zeros((0, 2)))
    with pytest.raises(SimulationError, match=r"options\['layout'\] places ORCA humans; crowd 'eth' is"):
        env.reset(options={"layout": layout})
    assert env.reset()[1]["seed"] == fresh.reset()[1]["seed"]  # the refused reset drew nothing
    with pytest.raises(SimulationError, match="crowd 'hotel' needs its Recording"):
        CrowdNavEnv(config=EnvConfig(crowd="hotel"))
    with pytest.raises(SimulationError, match="a recording replays a crowd"):
        CrowdNavEnv(recording=four_people())


def test_a_replayed_frame_renders():
    env = replay_env(render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.zeros((3, 2)))
    frame = env.render()
    assert frame is not None and frame.shape == (480, 640, 3)
