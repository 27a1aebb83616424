"""``EnvConfig.robot_spacing`` (``[env] robot_spacing``): the robots' neighbours, and so their goals, that far
apart in every formation, for an MPC whose d_min leaves no room on goals 1 m apart (the goal-room note)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.formations import robot_layout
from tests.cli_calls import one_line
from tests.cli_calls import run_cli as run


def test_the_row_at_a_spacing_by_hand():
    starts, goals = robot_layout(3, "row", spacing=1.3)
    np.testing.assert_allclose(starts, [[-1.3, -5.0], [0.0, -5.0], [1.3, -5.0]], rtol=0, atol=1e-12)
    np.testing.assert_allclose(goals, [[-1.3, 5.0], [0.0, 5.0], [1.3, 5.0]], rtol=0, atol=1e-12)


def test_the_wedge_at_a_spacing_is_its_lattice_at_that_spacing():
    # the wedge of 3: one robot ahead, two behind, ranks sqrt(3) / 2 spacings apart
    starts, _ = robot_layout(3, "wedge", spacing=1.5)
    d = np.linalg.norm(starts[:, None] - starts[None], axis=-1)[np.triu_indices(3, k=1)]
    np.testing.assert_allclose(d, [1.5, 1.5, 1.5], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.ptp(starts[:, 1]), 1.5 * math.sqrt(3) / 2, rtol=0, atol=1e-12)


def test_unset_is_each_formations_own_and_the_env_places_the_robots_so():
    np.testing.assert_array_equal(robot_layout(3, "row")[0], robot_layout(3, "row", spacing=1.0)[0])
    np.testing.assert_array_equal(robot_layout(5, "wedge")[0], robot_layout(5, "wedge", spacing=1.2)[0])
    obs = CrowdEnv(EnvConfig(robot_spacing=1.4)).reset(3, "circle", 5, 3)
    np.testing.assert_allclose(obs.robot_positions[:, 0], [-1.4, 0.0, 1.4], rtol=0, atol=1e-12)
    default = CrowdEnv().reset(3, "circle", 5, 3)
    np.testing.assert_array_equal(default.robot_positions, robot_layout(3, "row")[0])


@pytest.mark.parametrize("bad", [0.5, 2.6, math.nan, math.inf, True, "1.2"])
def test_a_spacing_outside_d_min_and_the_widest_is_refused(bad):
    with pytest.raises(
        SimulationError, match=r"EnvConfig.robot_spacing must be a number of metres in \[d_min"
    ):
        EnvConfig(robot_spacing=bad)


def test_the_command_line_takes_it_and_refuses_a_bad_one(tmp_path, capsys):
    report = tmp_path / "run.json"
    argv = ["simulate", "--controller", "straight", "--humans", "1", "--no-progress", "--json", str(report)]
    code, _, err = run(capsys, *argv, "--set", "env.robot_spacing=1.3")
    assert code == 0, err
    episode = json.loads(report.read_text())["episodes"][0]
    assert episode["config"]["env"]["robot_spacing"] == 1.3
    code, _, err = run(capsys, *argv, "--set", "env.robot_spacing=0.5")
    refusal = "--set env.robot_spacing: must be a number of metres in [d_min = 0.8, 2.5]"
    assert code == 2 and refusal in one_line(err)


def test_the_widest_spacing_stays_inside_the_gym_observations_bounds():
    """The gymnasium array clips coordinates at ``scene_bound``, which held the formations at their own
    spacing: a wider spacing must not put a start or goal outside it."""
    from crowdsim.formations import FORMATIONS, MAX_ROBOT_SPACING
    from crowdsim.gym_observation import scene_bound
    from crowdsim.scenarios import MAX_ROBOTS
    from crowdsim.world import V_PREF

    for formation in FORMATIONS:
        starts, goals = robot_layout(MAX_ROBOTS, formation, spacing=MAX_ROBOT_SPACING)
        assert np.abs(np.concatenate([starts, goals])).max() <= scene_bound(V_PREF, 1)


def test_a_replayed_crowd_takes_the_spacing_too():
    from crowdsim.replay import replay_episode
    from tests.crowdsim.test_replay import four_people

    rng = np.random.default_rng(0)
    ep = replay_episode(four_people(), "circle", 3, 3, 10, rng, radius=0.3, past=2, spacing=1.4)
    np.testing.assert_allclose(ep.robot_starts, robot_layout(3, "auto", spacing=1.4)[0], rtol=0, atol=0)


def test_a_replayed_crowd_refuses_a_radius_at_which_the_robots_overlap_as_orcas_does():
    """make_layout refused radius 0.55 m for the row's robots 1 m apart; a replay drew its robots from the
    same formation without the check, and ``--crowd eth_test --set world.radius=0.55`` ran the robots
    inside each other from the start."""
    from crowdsim.replay import replay_episode
    from tests.crowdsim.test_replay import four_people

    refusal = r"the row formation of 3 robots puts neighbours 1 m apart, in contact from the start"
    with pytest.raises(SimulationError, match=refusal):
        replay_episode(four_people(), "circle", 3, 3, 10, np.random.default_rng(0), radius=0.55, past=2)
    short = {"crowd": "eth", "radius": 0.55, "time_limit": 4.0, "timeout_margin": 0.0, "history_len": 3}
    env = CrowdEnv(EnvConfig(**short), four_people())  # 10 steps after 2 rows of history: its 13 rows
    with pytest.raises(SimulationError, match=refusal):
        env.reset(0, "circle", 3, 3)
    # a spacing that keeps them apart, or one robot, runs
    CrowdEnv(EnvConfig(**short, robot_spacing=1.2), four_people()).reset(0, "circle", 3, 3)
    env.reset(0, "circle", 3, 1)
