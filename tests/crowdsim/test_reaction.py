"""Reactive replays (crowdsim.reaction): real tracks that yield to the robots as ORCA's humans do, and are
the plain replay, bit for bit, wherever no robot is in the way."""

import numpy as np
import pytest

from crowdsim.env import CrowdEnv, EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.orca import OrcaParams
from crowdsim.reaction import CATCH_UP, MIN_SPEED, RETURN_TIME, reactive_step, reacts
from crowdsim.replay import CROWDS, Recording, ReplayEpisode, recorded

DT = 0.4
TIME_LIMIT = 16.0  # s
RADIUS = 0.31  # ORCA's: the agents' 0.3 m and CrowdNav's margin


def walk(person, rows, x0, dx, y):
    """Rows (frame, person, x, y) of ``person`` at ``rows`` of a 6-frame grid, walking ``dx`` m a row."""
    return [(6 * r, person, x0 + dx * (r - rows[0]), y) for r in rows]


def pair_and_crosser(name="eth"):
    """47 rows: 8 of history and an episode of ``TIME_LIMIT`` (38 steps). Two people (ids 1, 2) walk +x side
    by side 0.4 m apart (closer than ORCA keeps anyone) at y = 0.2 and -0.2, 0.4 m a row, on every row,
    through x = 0 at row 23, when the robots pushed up the y axis are there; a third (3) walks -x at y = 3
    from row 5 to 30."""
    rows = walk(1, range(47), -9.2, 0.4, 0.2) + walk(2, range(47), -9.2, 0.4, -0.2)
    rows += walk(3, range(5, 31), 6.0, -0.4, 3.0)
    return Recording.from_rows(name, np.array(rows), frame_step=6)


def episode(positions, present):
    """A ReplayEpisode of the given rows (no history), velocities the recorded steps."""
    positions = np.asarray(positions, dtype=float)
    present = np.asarray(present, dtype=bool)
    velocities = np.zeros_like(positions)
    moving = present[1:] & present[:-1]
    velocities[1:] = np.where(moving[..., None], np.diff(positions, axis=0) / DT, 0.0)
    return ReplayEpisode(
        robot_starts=np.zeros((0, 2)),
        robot_goals=np.zeros((0, 2)),
        positions=positions,
        velocities=velocities,
        present=present,
        observed=np.cumsum(present, axis=0),
        goals=positions[-1].copy(),
        past=0,
        start_row=0,
        people=np.arange(positions.shape[1]),
    )


def step(ep, row, positions, velocities, robots=None, robot_velocities=None):
    robots = np.zeros((0, 2)) if robots is None else robots
    robot_velocities = np.zeros_like(robots) if robot_velocities is None else robot_velocities
    return reactive_step(
        ep, row, positions, velocities, robots, robot_velocities, radius=RADIUS, params=OrcaParams(), dt=DT
    )


def test_every_recording_has_a_reactive_replay_that_plays_it():
    assert [c for c in CROWDS if reacts(c)] == [
        "eth_reactive",
        "hotel_reactive",
        "eth_test_reactive",
        "hotel_test_reactive",
    ]
    assert [recorded(c) for c in ("eth_test_reactive", "eth_test", "orca")] == ["eth_test", "eth_test", None]
    with pytest.raises(SimulationError, match="crowd must be one of .* got 'zara_reactive'"):
        recorded("zara_reactive")
    assert EnvConfig(crowd="hotel_reactive").crowd == "hotel_reactive"


def test_a_deflected_person_closes_a_third_of_the_gap_a_step_and_at_most_catch_up_speed():
    # one person walking +x at 1 m/s on y = 0 for three rows
    ep = episode([[[0.0, 0.0]], [[0.4, 0.0]], [[0.8, 0.0]]], [[True]] * 3)
    assert RETURN_TIME == 1.2 and CATCH_UP == 0.5
    # 0.3 m off the track: pulled back at 0.3 / 1.2 = 0.25 m/s, so 0.1 m of it goes in a step of 0.4 s
    positions, velocities, _ = step(ep, 1, np.array([[0.4, 0.3]]), np.array([[1.0, 0.0]]))
    np.testing.assert_allclose(positions, [[0.8, 0.2]], atol=1e-15)
    np.testing.assert_allclose(velocities, [[1.0, -0.25]], atol=1e-15)
    # 1.2 m off: the pull of 1 m/s is held to 0.5 m/s, 0.2 m a step
    positions, velocities, _ = step(ep, 1, np.array([[0.4, 1.2]]), np.array([[1.0, 0.0]]))
    np.testing.assert_allclose(positions, [[0.8, 1.0]], atol=1e-15)
    np.testing.assert_allclose(velocities, [[1.0, -0.5]], atol=1e-15)


def test_people_appear_where_recorded_and_stay_where_they_are_once_their_track_ends():
    # person 0 tracked on rows 0-1 then gone; person 1 appears at row 2
    positions = [[[0.0, 0.0], [5.0, 5.0]], [[0.4, 0.0], [5.0, 5.0]], [[0.4, 0.0], [5.4, 5.0]]]
    ep = episode(positions, [[True, False], [True, False], [False, True]])
    moved, velocities, _ = step(ep, 1, np.array([[0.4, 0.7], [5.0, 5.0]]), np.zeros((2, 2)))
    np.testing.assert_array_equal(moved, [[0.4, 0.7], [5.4, 5.0]])  # where it was deflected to; the track
    np.testing.assert_array_equal(velocities, np.zeros((2, 2)))  # zero where absent and where it appears


def test_a_standing_person_steps_aside_for_a_robot_coming_at_them_and_the_plain_replay_does_not():
    ep = episode([[[0.0, 0.0]]] * 3, [[True]] * 3)
    robot, robot_velocity = np.array([[-1.0, 0.0]]), np.array([[1.0, 0.0]])
    positions, velocities, _ = step(ep, 1, np.zeros((1, 2)), np.zeros((1, 2)), robot, robot_velocity)
    speed = float(np.linalg.norm(velocities[0]))
    assert 0.0 < speed <= MIN_SPEED + 1e-12
    np.testing.assert_allclose(positions, DT * velocities)


def walk_env(crowd, robots_visible=True, n_robots=3, seed=0):
    """A whole episode among ``pair_and_crosser``'s people, the robots pushed up the y axis."""
    config = EnvConfig(crowd=crowd, robots_visible=robots_visible, time_limit=TIME_LIMIT)
    env = CrowdEnv(config, pair_and_crosser())
    obs = env.reset(seed, "perpendicular", 3, n_robots)
    done = False
    while not done:
        obs, done, _ = env.step(np.tile([0.0, 0.5], (n_robots, 1)))
    return env.trajectory()


@pytest.mark.parametrize("n_robots, visible", [(0, True), (3, False)])
def test_without_a_robot_to_see_the_reactive_replay_is_the_plain_one_bit_for_bit(n_robots, visible):
    # the pair walks 0.4 m apart throughout: people never push each other apart
    plain = walk_env("eth", visible, n_robots)
    reactive = walk_env("eth_reactive", visible, n_robots)
    np.testing.assert_array_equal(reactive.human_positions, plain.human_positions)
    np.testing.assert_array_equal(reactive.human_velocities, plain.human_velocities)
    np.testing.assert_array_equal(reactive.robot_positions, plain.robot_positions)


def test_people_yield_to_the_robots_in_their_way_and_walk_their_tracks_again_after():
    plain, reactive = walk_env("eth"), walk_env("eth_reactive")
    gap = np.linalg.norm(reactive.human_positions[:, :, None] - reactive.robot_positions[:, None], axis=-1)[
        reactive.human_present
    ].min()
    plain_gap = np.linalg.norm(plain.human_positions[:, :, None] - plain.robot_positions[:, None], axis=-1)
    assert plain_gap[plain.human_present].min() < 0.6  # the pair walks into the robots' row
    assert gap > plain_gap[plain.human_present].min()
    off = np.linalg.norm(reactive.human_positions - plain.human_positions, axis=-1)
    deflected = np.flatnonzero(off.max(axis=0) > 0.05)
    np.testing.assert_array_equal(deflected, [0, 1])  # the pair; the third person meets no robot
    for person in deflected:  # once the robots are by, the gap closes at the catch-up speed, 0.2 m a step
        after = off[off[:, person].argmax() :, person]
        assert len(after) > 3
        np.testing.assert_allclose(np.diff(after), -CATCH_UP * DT, atol=1e-9)


def test_the_observed_history_holds_the_recorded_past_then_where_people_really_were():
    env = CrowdEnv(EnvConfig(crowd="eth_reactive", time_limit=TIME_LIMIT), pair_and_crosser())
    env.reset(0, "perpendicular", 3, 3)
    for _ in range(12):
        obs, _, _ = env.step(np.tile([0.0, 0.5], (3, 1)))
    trajectory = env.trajectory()
    np.testing.assert_array_equal(obs.history[:, 3:], trajectory.human_positions[-obs.history.shape[0] :])
    np.testing.assert_array_equal(obs.human_positions, trajectory.human_positions[-1])


def test_a_reactive_crowd_needs_the_recording_it_plays():
    with pytest.raises(SimulationError, match="crowd 'eth_reactive' needs its Recording \\(named 'eth'\\)"):
        CrowdEnv(EnvConfig(crowd="eth_reactive"), pair_and_crosser("hotel"))
