"""Replayed crowds (crowdsim.replay): real tracks played back as the simulator's humans, the window and the
people an episode takes, and the metrics that count a human only while it is tracked."""

import math

import numpy as np
import pytest

from crowdsim.env import CrowdEnv, EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.metrics import Trajectory, episode_metrics
from crowdsim.replay import Recording, replay_episode
from crowdsim.scenarios import Layout


def walk(person, rows, x0, dx, y):
    """Rows (frame, person, x, y) of ``person`` at ``rows`` of a 6-frame grid, walking ``dx`` m a row."""
    return [(6 * r, person, x0 + dx * (r - rows[0]), y) for r in rows]


def four_people(name="eth"):
    """13 rows (frames 0..72). A (id 1) and B (2) are tracked on rows 3..10 at y = 1 and -1, walking +x and
    -x 0.4 m a row; C (3) and D (4) on every row at y = 8 and -8, the same. Mirror images of each other, so
    the median position is (0, 0) exactly, and every step runs along x: the flow is (1, 0)."""
    rows = walk(1, range(3, 11), -2.0, 0.4, 1.0) + walk(2, range(3, 11), 2.0, -0.4, -1.0)
    rows += walk(3, range(13), -2.4, 0.4, 8.0) + walk(4, range(13), 2.4, -0.4, -8.0)
    return Recording.from_rows(name, np.array(rows), frame_step=6)


def test_a_recording_holds_each_track_on_the_frame_grid_and_knows_its_gaps():
    rows = [(0, 7, 1.0, 2.0), (6, 7, 1.5, 2.0), (18, 9, 0.0, 0.0), (24, 9, 0.1, 0.0), (27, 9, 0.2, 0.0)]
    rec = Recording.from_rows("hotel", np.array([*rows, (33, 9, 0.3, 0.0)]), frame_step=6)
    # frame 12: nobody annotated, a row with nobody tracked; 27 is off the grid: a grid of its own from there
    np.testing.assert_array_equal(rec.frames, [0, 6, 12, 18, 24, 27, 33])
    assert rec.positions.shape == (7, 2, 2)
    np.testing.assert_array_equal(rec.positions[:, 0, 0], [1.0, 1.5] + [np.nan] * 5)
    np.testing.assert_array_equal(rec.positions[:, 1, 0], [np.nan] * 3 + [0.0, 0.1, 0.2, 0.3])
    # rows in a row on one grid: not 24 -> 27, nor across it
    np.testing.assert_array_equal(rec.window_starts(1), [0, 1, 2, 3, 5])
    np.testing.assert_array_equal(rec.window_starts(3), [0, 1])
    with pytest.raises(SimulationError, match="frame_step must be an int >= 1, got 0"):
        Recording.from_rows("hotel", np.array(rows), frame_step=0)


def test_a_frame_step_of_numpys_int_is_taken_and_a_dt_not_a_number_refused():
    """from_rows refused np.int64(6) as "frame_step must be an int >= 1, got np.int64(6)" (a frame step
    computed from the frames, np.diff(frames).min(), is one), took dt "0.4" as 0.4 and dt -0.4 (a negative
    fastest speed in ``extent``), and raised numpy's ValueError naming nothing for "abc"."""
    rows = np.array(walk(1, range(4), 0.0, 0.4, 0.0))
    step = np.diff(np.unique(rows[:, 0])).astype(np.int64).min()
    rec = Recording.from_rows("eth", rows, frame_step=step)
    assert rec.frame_step == 6 and type(rec.frame_step) is int
    for dt in ("0.4", "abc", -0.4, 0.0, math.nan, True):
        with pytest.raises(
            SimulationError, match=r"^recording 'eth': dt must be a finite number of seconds > 0"
        ):
            Recording.from_rows("eth", rows, frame_step=6, dt=dt)  # type: ignore[arg-type]
    np.testing.assert_allclose(Recording.from_rows("eth", rows, 6, dt=np.float64(0.4)).extent(), (0.6, 1.0))


@pytest.mark.parametrize(
    ("spoilt", "message"),
    [
        (
            (6, 7, 9.0, 9.0),
            "recording 'hotel': rows hold 1 duplicate (frame, pedestrian) row; the first is rows[2]: "
            "frame 6, pedestrian 7, already at rows[1]",
        ),
        (
            (12, 7.5, 9.0, 9.0),
            "recording 'hotel': frame and pedestrian ids in rows must be integers: rows[2] has frame 12.0, "
            "pedestrian 7.5 (1 of 3 rows)",
        ),
        (
            (12.5, 9, 9.0, 9.0),
            "recording 'hotel': frame and pedestrian ids in rows must be integers: rows[2] has frame 12.5, "
            "pedestrian 9.0 (1 of 3 rows)",
        ),
    ],
    ids=["duplicate", "fractional-id", "fractional-frame"],
)
def test_rows_that_name_one_person_twice_at_a_frame_or_no_whole_frame_or_id_are_refused(spoilt, message):
    """read_obsmat refuses these (naming the file's line), but from_rows kept the last of two rows of one
    person at one frame, and truncated 7.5 to 7, merging two people's tracks into one."""
    rows = np.array([(0, 7, 1.0, 2.0), (6, 7, 1.5, 2.0), spoilt])
    with pytest.raises(SimulationError) as info:
        Recording.from_rows("hotel", rows, frame_step=6)
    assert str(info.value) == message


def test_a_count_of_one_row_is_said_in_the_singular():
    """One row of one row, "(1 of 1 rows)"; two duplicates keep the plural."""
    with pytest.raises(SimulationError, match=r"pedestrian 7\.5 \(1 of 1 row\)$"):
        Recording.from_rows("hotel", np.array([(0, 7.5, 1.0, 2.0)]), frame_step=6)
    rows = np.array([(0, 7, 1.0, 2.0), (0, 7, 1.5, 2.0), (0, 7, 2.0, 2.0)])
    with pytest.raises(SimulationError, match=r"rows hold 2 duplicate \(frame, pedestrian\) rows; the first"):
        Recording.from_rows("hotel", rows, frame_step=6)


def test_frames_too_far_apart_or_too_large_are_refused_before_any_grid_is_filled():
    """Two frames a billion ids apart on a step of 1 filled a grid of a billion rows (16 GB a pedestrian),
    and a frame of 1e300 became an arbitrary int64."""
    from crowdsim.replay import MAX_GRID_CELLS

    far = np.array([(0, 7, 1.0, 2.0), (1, 7, 1.5, 2.0), (10**9, 8, 0.0, 0.0)])
    with pytest.raises(SimulationError) as info:
        Recording.from_rows("eth", far, frame_step=1)
    assert str(info.value) == (
        f"recording 'eth': frames 0..{10**9} on a step of 1 make {10**9 + 1} rows for 2 pedestrians, more "
        f"than the {MAX_GRID_CELLS} cells a recording may hold (frames far apart on one grid)"
    )
    assert (10**9 - 1) % 6  # on a step of 6 the far frame is off the grid: a jump, no row filled
    assert len(Recording.from_rows("eth", far, frame_step=6).frames) == 3
    with pytest.raises(SimulationError, match="frame and pedestrian ids must be within"):
        Recording.from_rows("eth", np.array([(0, 7, 1.0, 2.0), (1e300, 7, 1.5, 2.0)]), frame_step=1)


def test_no_window_spans_jumps_off_the_grid_that_add_up_to_whole_steps():
    # ids shifted by 3 frames (6 -> 9) and back (9 -> 18): frames 6, 9, 18 span 12 = 2 steps, but are no two
    # steps of 0.4 s, and their replay would walk 0.2 s and 0.6 s of motion as 0.4 s each
    rows = [(frame, 1, 0.1 * frame, 0.0) for frame in (0, 6, 9, 18, 24)]
    rec = Recording.from_rows("eth", np.array(rows), frame_step=6)
    np.testing.assert_array_equal(rec.frames, [0, 6, 9, 18, 24])
    np.testing.assert_array_equal(rec.window_starts(1), [0, 3])
    assert len(rec.window_starts(2)) == len(rec.window_starts(3)) == 0


def test_the_flow_is_the_median_position_and_the_main_direction_of_the_steps():
    centre, direction = four_people().flow()
    np.testing.assert_array_equal(centre, [0.0, 0.0])
    np.testing.assert_allclose(direction, [1.0, 0.0], atol=1e-12)


def test_an_episode_takes_the_people_closest_to_the_robots_path_held_outside_their_tracks():
    # 13 rows = 2 of history + 10 steps + 1: the only window starts at row 0, the episode at row 2
    ep = replay_episode(
        four_people(), "perpendicular", 2, 3, 10, np.random.default_rng(0), radius=0.3, past=2
    )
    # the robots go from y = -5 to 5 between x = -1 and 1: A and B cross that box, C and D pass 3 m from it
    np.testing.assert_array_equal(ep.people, [0, 1])
    assert (ep.start_row, ep.past) == (2, 2)
    np.testing.assert_array_equal(ep.present[:, 0], [False] * 3 + [True] * 8 + [False] * 2)
    np.testing.assert_array_equal(ep.observed[:, 0], [0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 0, 0])
    # perpendicular: the flow stays along x; before its track A stands where it starts, after where it ends
    np.testing.assert_allclose(ep.positions[:4, 0], [[-2.0, 1.0]] * 4)
    np.testing.assert_allclose(ep.positions[10:, 0], [[0.8, 1.0]] * 3)
    np.testing.assert_allclose(ep.positions[:, 1], -ep.positions[:, 0])
    # its recorded steps, 0.4 m a row of 0.4 s: 1 m/s, zero where it appears and where it is not tracked
    np.testing.assert_allclose(ep.velocities[:, 0, 0], [0.0] * 4 + [1.0] * 7 + [0.0] * 2, atol=1e-12)
    np.testing.assert_allclose(ep.goals, [[0.8, 1.0], [-0.8, -1.0]])


def test_a_person_unseen_inside_their_track_stands_where_last_seen():
    """A (id 1) unseen on rows 6 and 7 of its track 3..10 (BIWI's files have no such gap; one's own may):
    those rows stood at NaN, and every recorded episode failed ("not plain JSON")."""
    rows = walk(1, [3, 4, 5, 8, 9, 10], -2.0, 0.4, 1.0) + walk(2, range(3, 11), 2.0, -0.4, -1.0)
    rows += walk(3, range(13), -2.4, 0.4, 8.0) + walk(4, range(13), 2.4, -0.4, -8.0)
    recording = Recording.from_rows("eth", np.array(rows), frame_step=6)
    ep = replay_episode(recording, "perpendicular", 2, 3, 10, np.random.default_rng(0), radius=0.3, past=2)
    np.testing.assert_array_equal(ep.people, [0, 1])
    assert np.isfinite(ep.positions).all()
    seen = [False] * 3 + [True] * 3 + [False] * 2 + [True] * 3 + [False] * 2
    np.testing.assert_array_equal(ep.present[:, 0], seen)
    # rows 5..7 at row 5's -2.0 + 2 x 0.4 = -1.2 m; row 8 at -2.0 + 5 x 0.4 = 0.0 (walk counts from row 3)
    np.testing.assert_allclose(ep.positions[5:9, 0, 0], [-1.2, -1.2, -1.2, 0.0], atol=1e-12)
    np.testing.assert_allclose(ep.velocities[5:9, 0, 0], [1.0, 0.0, 0.0, 0.0], atol=1e-12)


def test_the_circle_scenario_turns_the_flow_along_the_robots_path_and_more_people_come_in_order():
    ep = replay_episode(four_people(), "circle", 3, 3, 10, np.random.default_rng(0), radius=0.3, past=2)
    # turned by +90 degrees, (x, y) -> (-y, x): A walks up the robots' path at x = -1; C, 8 m aside, is the
    # third closest, level with D, and comes first by its id
    np.testing.assert_array_equal(ep.people, [0, 1, 2])
    np.testing.assert_allclose(ep.positions[3, 0], [-1.0, -2.0], atol=1e-12)
    np.testing.assert_allclose(ep.velocities[5, 0], [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(ep.positions[2, 2], [-8.0, -1.6], atol=1e-12)


def test_an_episode_nobody_can_make_is_refused_with_the_most_found():
    with pytest.raises(
        SimulationError, match=r"has 5 pedestrians in its first 4 s .*clear \(the most in one window: 4\);"
    ):
        replay_episode(four_people(), "circle", 5, 3, 10, np.random.default_rng(0), radius=0.3, past=2)
    with pytest.raises(SimulationError, match="no 14 consecutive steps"):
        replay_episode(four_people(), "circle", 2, 3, 11, np.random.default_rng(0), radius=0.3, past=2)
    # the crowd the user chose is named beside the recording it replays ("hotel_reactive" said 'hotel' alone)
    name = four_people().name
    with pytest.raises(SimulationError, match=rf"^crowd '{name}_reactive' \(recording '{name}'\) has no 14"):
        replay_episode(four_people(), "circle", 2, 3, 11, np.random.default_rng(0), radius=0.3, past=2,
                       crowd=f"{name}_reactive")  # fmt: skip
    # someone standing on the middle robot's start at the first step (5 at (0, -5), 7 at (0, 5), 6 and 8
    # walking along x through the centre): the only window cannot leave the start clear
    rows = walk(5, range(13), 0.0, 0.0, -5.0) + walk(7, range(13), 0.0, 0.0, 5.0)
    rows += walk(6, range(13), -2.4, 0.4, 0.0) + walk(8, range(13), 2.4, -0.4, 0.0)
    rec = Recording.from_rows("eth", np.array(rows), frame_step=6)
    with pytest.raises(
        SimulationError,
        match=r"and the robots. starts clear \(200 draws with enough had someone within 0.8 m of a robot.s "
        r"start; the most in one window: 4\)",
    ):
        replay_episode(rec, "perpendicular", 1, 3, 10, np.random.default_rng(0), radius=0.3, past=2)


def test_a_history_too_long_for_the_recording_is_said_to_be_the_history_not_the_time_limit():
    """four_people's 13 rows: 10 steps after 2 rows of history do not fit but 1 step does (shorten the time
    limit); after 12 rows of history not even 1 step fits, where the refusal still said "shorten [env]
    time_limit" of an episode of 0.4 s."""
    rng = np.random.default_rng(0)
    with pytest.raises(SimulationError, match=r"no 14 consecutive steps .*: shorten \[env\] time_limit$"):
        replay_episode(four_people(), "circle", 2, 3, 11, rng, radius=0.3, past=2)
    with pytest.raises(
        SimulationError,
        match=r"no 14 consecutive steps \(an episode of 0.4 s after 12 of observed history\): shorten "
        r"\[world\] obs_len: the history alone does not fit$",
    ):
        replay_episode(four_people(), "circle", 2, 3, 1, rng, radius=0.3, past=12)
    replay_episode(four_people(), "circle", 2, 3, 1, rng, radius=0.3, past=11)  # 13 rows: it fits


def test_the_simulator_plays_the_tracks_back_with_their_past_presence_and_track_lengths():
    # history_len 3: the 2 rows before the episode are its observed past; time limit 4 s = 10 steps
    config = EnvConfig(crowd="eth", history_len=3, time_limit=4.0, timeout_margin=0.0)
    env = CrowdEnv(config, four_people())
    obs = env.reset(0, "perpendicular", 2, 3)
    np.testing.assert_allclose(obs.human_positions, [[-2.0, 1.0], [2.0, -1.0]])  # held where A and B begin
    np.testing.assert_array_equal(obs.human_present, [False, False])
    np.testing.assert_array_equal(obs.human_observed, [0, 0])
    for _ in range(3):
        obs, _, info = env.step(np.zeros((3, 2)))
    assert info["orca_lp3"] == 0
    np.testing.assert_allclose(obs.human_positions[0], [-1.2, 1.0])  # row 5: tracked since row 3
    np.testing.assert_array_equal(obs.human_observed, [3, 3])
    np.testing.assert_allclose(obs.human_velocities[0], [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(obs.history[:, 3, 0], [-2.0, -1.6, -1.2])  # rows 3..5, A (robots first)
    done = False
    while not done:
        obs, done, info = env.step(np.zeros((3, 2)))
    traj = env.trajectory()
    assert traj.n_steps == 10 and info["timeout"]
    np.testing.assert_array_equal(traj.human_present[:, 0], [False] + [True] * 8 + [False] * 2)
    np.testing.assert_allclose(traj.human_positions[-1], [[0.8, 1.0], [-0.8, -1.0]])


def test_a_replayed_crowd_needs_its_recording_the_recorded_step_and_no_layout():
    with pytest.raises(SimulationError, match="crowd must be one of"):
        EnvConfig(crowd="zara")
    with pytest.raises(SimulationError, match="dt must be 0.4 s, got 0.2"):
        EnvConfig(crowd="eth", dt=0.2)
    with pytest.raises(SimulationError, match="crowd 'eth' needs its Recording"):
        CrowdEnv(EnvConfig(crowd="eth"))
    with pytest.raises(SimulationError, match="needs its Recording .named 'hotel'"):
        CrowdEnv(EnvConfig(crowd="hotel"), four_people("eth"))
    with pytest.raises(SimulationError, match="not 'orca'"):
        CrowdEnv(EnvConfig(), four_people())
    ten_hertz = Recording("eth", np.arange(4), 1, np.zeros((4, 1, 2)), dt=0.1)
    with pytest.raises(SimulationError, match="recording 'eth' has steps of 0.1 s, but dt is 0.4 s"):
        CrowdEnv(EnvConfig(crowd="eth"), ten_hertz)
    env = CrowdEnv(EnvConfig(crowd="eth", time_limit=4.0, timeout_margin=0.0, history_len=3), four_people())
    layout = Layout(np.zeros((1, 2)), np.ones((1, 2)), np.zeros((0, 2)), np.zeros((0, 2)))
    with pytest.raises(SimulationError, match="is replayed: use reset"):
        env.reset_layout(layout)
    with pytest.raises(SimulationError, match="unknown scenario"):
        env.reset(0, "square", 2, 3)


def test_a_step_just_off_the_recordings_is_refused_in_full_not_rounded_onto_it():
    """ ":g" wrote 0.4000001 as 0.4, so that the refusals read "dt must be 0.4 s, got 0.4" and "has steps of
    0.4 s, but dt is 0.4 s" (``crowdmpc simulate --crowd eth_test --set world.dt=0.4000001``; a recording's
    dt of np.float32(0.4))."""
    with pytest.raises(SimulationError, match=r"so dt must be 0.4 s, got 0.4000001$"):
        EnvConfig(crowd="eth", dt=0.4000001)
    with pytest.raises(SimulationError, match=r"got 0.4000000059604645$"):
        EnvConfig(crowd="eth", dt=np.float32(0.4))
    off = Recording("eth", np.arange(4), 1, np.zeros((4, 1, 2)), dt=float(np.float32(0.4)))
    with pytest.raises(SimulationError, match=r"has steps of 0.4000000059604645 s, but dt is 0.4 s: "):
        CrowdEnv(EnvConfig(crowd="eth"), off)


def masked_trajectory(present):
    """One robot standing at the origin. Human 0 stands 0.1 m from it, walking into it; human 1 comes from
    the other side: at (-2, 0) at row 0 (held there before its track), then (1.5, 0) and (1, 0)."""
    humans = np.array([[[0.1, 0.0], [-2.0, 0.0]], [[0.1, 0.0], [1.5, 0.0]], [[0.1, 0.0], [1.0, 0.0]]])
    velocities = np.zeros_like(humans)
    velocities[:, 0] = [-1.0, 0.0]
    return Trajectory(
        robot_positions=np.zeros((3, 1, 2)), robot_velocities=np.zeros((3, 1, 2)), human_positions=humans,
        human_velocities=velocities, robot_goals=np.array([[0.0, 5.0]]), human_goals=humans[-1],
        robot_accelerations=np.zeros((2, 1, 2)), dt=0.4, radius=0.3, human_present=present,
    )  # fmt: skip


def test_the_metrics_count_a_human_only_where_it_is_tracked():
    everyone = episode_metrics(masked_trajectory(None))
    assert everyone.min_distance == pytest.approx(0.1) and everyone.discomfort
    assert everyone.min_distance_between_steps == 0.0  # human 1's jump from (-2, 0) passes the robot
    present = np.array([[False, False], [False, True], [False, True]])
    tracked = episode_metrics(masked_trajectory(present))
    # human 0 is never tracked; human 1 is nearest at row 2, 1 m away, and its jump from its held row 0
    # (through the robot) is no motion: the step from row 0 counts only where it is tracked at both ends
    assert tracked.min_distance == 1.0 and tracked.min_distance_between_steps == 1.0
    assert not (tracked.collision or tracked.contact or tracked.discomfort or tracked.collision_between_steps)
    assert (tracked.collision_steps, tracked.discomfort_steps) == (0, 0)
    assert tracked.min_distance_humans == math.inf  # never two tracked at once
    assert everyone.min_distance_humans == pytest.approx(0.9)


def test_what_a_recording_keeps_for_its_episodes_cannot_be_changed_in_place():
    """turned() and flow() handed out the arrays the recording keeps for every later episode: a caller
    centring ``turned("circle")`` in place (NaN where nobody is tracked) left no window with anyone in it."""
    rec = four_people()
    first = replay_episode(rec, "circle", 2, 3, 10, np.random.default_rng(0), radius=0.3, past=2)
    for kept in (rec.turned("circle"), *rec.flow()):
        with pytest.raises(ValueError, match="read-only"):
            kept -= 1.0
    again = replay_episode(rec, "circle", 2, 3, 10, np.random.default_rng(0), radius=0.3, past=2)
    np.testing.assert_array_equal(again.positions, first.positions)
    rows = rec.turned("circle").copy()  # a copy is the caller's
    rows -= 1.0
