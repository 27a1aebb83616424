"""Robot-robot contact (not a metric of the paper), on constructed trajectories by hand: two robots whose
centres come closer than the sum of the radii (0.6 m at radius 0.3 m) touch; the robot-human metrics beside
them keep their values."""

import math

import pytest

from crowdsim.metrics import ROBOT_CONTACT, EpisodeMetrics, Trajectory, aggregate, episode_metrics
from tests.crowdsim.test_metrics_between_steps import make_traj
from tests.same_metrics import same_metrics


def pair(gaps) -> Trajectory:
    """Two robots on the x axis, ``gaps[k]`` m apart at row k (robot 0 at -gap/2, robot 1 at +gap/2)."""
    return make_traj([[[-g / 2, 0.0], [g / 2, 0.0]] for g in gaps])


# Rows 0..4 at 2.0, 1.0, 0.5, 0.55, 1.0 m: below 0.6 m at rows 2 and 3.
CLOSE = (2.0, 1.0, 0.5, 0.55, 1.0)
# Rows 0..3 at 2.0, 1.0, 0.7, 1.0 m: never below 0.6 m.
APART = (2.0, 1.0, 0.7, 1.0)


def test_two_robots_0_5_m_apart_touch():
    m = episode_metrics(pair(CLOSE))
    assert m.min_distance_robots == pytest.approx(0.5)
    assert m.robot_contact is True and m.robot_contact_steps == 2
    # robot-human metrics as before: no human, nothing counted
    assert not m.contact and not m.collision and m.contact_steps == 0 and m.min_distance == math.inf


def test_two_robots_0_7_m_apart_do_not():
    m = episode_metrics(pair(APART))
    assert m.min_distance_robots == pytest.approx(0.7)
    assert m.robot_contact is False and m.robot_contact_steps == 0


def test_exactly_the_sum_of_the_radii_is_no_contact():
    m = episode_metrics(pair((2.0, 0.6)))
    assert m.min_distance_robots == 0.6 and not m.robot_contact and m.robot_contact_steps == 0


def test_the_closest_pair_of_three_robots_counts_at_each_state():
    # Row 0: robots 0-1 0.5 m apart; row 1: robots 1-2 0.4 m apart (0-1 now 2 m); row 2: all 2 m or more.
    rows = [
        [[0.0, 0.0], [0.5, 0.0], [5.0, 0.0]],
        [[0.0, 0.0], [2.0, 0.0], [2.4, 0.0]],
        [[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]],
    ]
    m = episode_metrics(make_traj(rows))
    assert m.robot_contact and m.robot_contact_steps == 2
    assert m.min_distance_robots == pytest.approx(0.4)


def test_one_robot_has_no_contact():
    m = episode_metrics(make_traj([[[0.0, 0.0]], [[0.0, 1.0]]]))
    assert m.min_distance_robots == math.inf
    assert m.robot_contact is False and m.robot_contact_steps == 0


def test_round_trip_and_a_record_written_before_the_fields():
    m = episode_metrics(pair(CLOSE))
    record = m.as_dict()
    assert (record["robot_contact"], record["robot_contact_steps"]) == (True, 2)
    assert list(record)[-4:] == list(ROBOT_CONTACT)  # added at the end: older records keep their order
    assert same_metrics(EpisodeMetrics.from_dict(record), m)
    old = {k: v for k, v in record.items() if k not in ROBOT_CONTACT}
    rebuilt = EpisodeMetrics.from_dict(old)
    assert rebuilt.robot_contact is None and rebuilt.robot_contact_steps is None
    assert rebuilt.robot_contact_between_steps is None and rebuilt.min_distance_robots_between_steps is None
    assert rebuilt.min_distance_robots == pytest.approx(0.5) and rebuilt.collision_steps == 0


def test_aggregate_rate_count_and_step_frequency():
    close, apart = episode_metrics(pair(CLOSE)), episode_metrics(pair(APART))
    out = aggregate([close, apart, apart, apart])
    assert (out["robot_contact_count"], out["robot_contact_rate"]) == (1, 25.0)
    # 2 states of 5 + 4 + 4 + 4 = 17
    assert out["robot_contact_step_freq"] == pytest.approx(100.0 * 2 / 17)
    assert out["contact_rate"] == 0.0 and out["contact_step_freq"] == 0.0  # robot-human, unchanged


def test_aggregate_is_nan_when_some_episode_lacks_the_field():
    close = episode_metrics(pair(CLOSE))
    old = EpisodeMetrics.from_dict({k: v for k, v in close.as_dict().items() if k not in ROBOT_CONTACT})
    out = aggregate([close, old])
    assert math.isnan(out["robot_contact_rate"]) and math.isnan(out["robot_contact_count"])
    assert math.isnan(out["robot_contact_step_freq"])
    assert out["contact_rate"] == 0.0 and out["collision_step_freq"] == 0.0  # the others still count


# Two robots swapping sides 0.4 m apart laterally: relative position (2, -0.4) then (-2, -0.4) m, so the
# recorded states are 2.04 m apart and the straight motion between them passes 0.4 m apart at s = 1/2.
SWAP = [[[-1.0, 0.2], [1.0, -0.2]], [[1.0, 0.2], [-1.0, -0.2]]]


def test_robots_that_cross_within_a_step_touch_between_steps_only():
    m = episode_metrics(make_traj(SWAP))
    assert m.min_distance_robots == pytest.approx(math.hypot(2.0, 0.4))
    assert not m.robot_contact and m.robot_contact_steps == 0
    assert m.min_distance_robots_between_steps == pytest.approx(0.4)
    assert m.robot_contact_between_steps is True


def test_between_steps_takes_the_closest_pair_of_three_and_never_exceeds_the_states():
    # robots 0-1 cross 1.0 m apart laterally (no contact); robot 2 follows robot 1 on its line, 0.7 m
    # behind it, then 0.55 m; robots 0-2 never come closer than their 1.0 m lateral offset
    rows = [
        [[-1.0, 0.5], [1.0, -0.5], [1.7, -0.5]],
        [[1.0, 0.5], [-1.0, -0.5], [-0.45, -0.5]],
    ]
    m = episode_metrics(make_traj(rows))
    assert m.min_distance_robots == pytest.approx(0.55) and m.robot_contact_steps == 1
    assert m.min_distance_robots_between_steps == pytest.approx(0.55)
    assert m.robot_contact_between_steps is True
    apart = episode_metrics(make_traj([row[:2] for row in rows]))
    assert apart.min_distance_robots_between_steps == pytest.approx(1.0)
    assert not apart.robot_contact_between_steps


def test_one_robot_is_never_in_contact_between_steps():
    m = episode_metrics(make_traj([[[0.0, 0.0]], [[0.0, 1.0]]]))
    assert m.min_distance_robots_between_steps == math.inf and m.robot_contact_between_steps is False
    assert m.as_dict()["min_distance_robots_between_steps"] is None  # inf written as null, read back as inf
    assert EpisodeMetrics.from_dict(m.as_dict()).min_distance_robots_between_steps == math.inf


def test_aggregate_counts_robot_contact_between_steps():
    swap, apart = episode_metrics(make_traj(SWAP)), episode_metrics(pair(APART))
    out = aggregate([swap, apart])
    assert (out["robot_contact_between_steps_count"], out["robot_contact_between_steps_rate"]) == (1, 50.0)
    assert (out["robot_contact_count"], out["robot_contact_rate"]) == (0, 0.0)
    # a record of the thirty-fourth session: robot_contact but not its between-step figures
    older = EpisodeMetrics.from_dict({k: v for k, v in swap.as_dict().items() if k not in ROBOT_CONTACT[2:]})
    out = aggregate([older, apart])
    assert math.isnan(out["robot_contact_between_steps_rate"]) and out["robot_contact_count"] == 0
