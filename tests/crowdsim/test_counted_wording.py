"""One robot or one pedestrian is counted in the singular in the simulator's refusals ("the episode's 1
robots", "with 1 robots after 10000 draws", "has 1 pedestrians"), where runs of one robot or one human are
allowed: crowdsim.errors.counted, crowdsim's own, as predictors.text_table.counted is the pipelines'."""

import math

import numpy as np
import pytest

from crowdsim import scenarios
from crowdsim.errors import SimulationError, counted
from crowdsim.gym_env import CrowdNavEnv
from crowdsim.gym_wrappers import VelocityControl
from crowdsim.replay import MAX_GRID_CELLS, Recording, replay_episode
from crowdsim.scenarios import make_layout


def test_counted_says_one_in_the_singular_and_any_other_number_in_the_plural():
    assert [counted(n, "robot") for n in (0, 1, 2)] == ["0 robots", "1 robot", "2 robots"]
    assert [counted(n, "entry", "entries") for n in (1, 3)] == ["1 entry", "3 entries"]
    assert counted(np.int64(1), "pedestrian") == "1 pedestrian"  # a numpy count, as len() or .sum() give


def test_a_layout_too_spread_to_sample_counts_one_robot_and_one_draw(monkeypatch):
    rng = np.random.default_rng(0)
    with pytest.raises(SimulationError, match=r"in scenario 'circle' with 1 robot after 10000 draws, each"):
        make_layout("circle", 1, 1, rng, spawn_separation=50.0)
    monkeypatch.setattr(scenarios, "MAX_TRIES", 1)
    with pytest.raises(SimulationError, match=r"with 3 robots after 1 draw, each start and goal 50.6 m"):
        make_layout("circle", 1, 3, rng, spawn_separation=50.0)


@pytest.mark.parametrize("velocity", [False, True], ids=["accelerations", "velocities"])
def test_a_non_finite_action_counts_one_robot_and_one_entry(velocity):
    env = CrowdNavEnv(n_robots=3, n_humans=1)
    env = VelocityControl(env) if velocity else env
    word = "velocity action" if velocity else "action"
    env.reset(seed=0, options={"n_robots": 1})
    with pytest.raises(SimulationError) as one:
        env.step(np.array([[math.inf, 0.0], [0.0, 0.0], [0.0, 0.0]]))
    assert str(one.value) == f"{word} must be finite for the episode's 1 robot, got 1 non-finite entry"
    env.reset(seed=0, options={"n_robots": 2})
    with pytest.raises(SimulationError) as two:  # as before
        env.step(np.array([[math.nan, math.nan], [0.0, 0.0], [0.0, 0.0]]))
    assert str(two.value) == f"{word} must be finite for the episode's 2 robots, got 2 non-finite entries"


def test_a_recording_too_far_apart_counts_its_one_pedestrian():
    far = np.array([(0, 7, 1.0, 2.0), (10**9, 7, 0.0, 0.0)])
    with pytest.raises(SimulationError) as info:
        Recording.from_rows("eth", far, frame_step=1)
    assert str(info.value) == (
        f"recording 'eth': frames 0..{10**9} on a step of 1 make {10**9 + 1} rows for 1 pedestrian, more "
        f"than the {MAX_GRID_CELLS} cells a recording may hold (frames far apart on one grid)"
    )


def test_an_episode_of_one_pedestrian_nobody_can_make_counts_it_so():
    """Two people standing still at (0, -5) and (0, 5) all along (as test_replay's blocked start): whoever a
    window takes stands on a robot's start."""
    rows = [(6 * r, person, 0.0, y) for person, y in ((5, -5.0), (6, 5.0)) for r in range(13)]
    recording = Recording.from_rows("eth", np.array(rows), frame_step=6)
    with pytest.raises(SimulationError) as info:
        replay_episode(recording, "circle", 1, 3, 10, np.random.default_rng(0), radius=0.3, past=2)
    assert str(info.value).startswith(
        "recording 'eth': no window in 200 draws has 1 pedestrian in its first 4 s and the robots' starts "
        "clear (200 draws with enough had someone within 0.8 m of a robot's start;"
    )
