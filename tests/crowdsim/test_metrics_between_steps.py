"""The between-step metrics (linear motion within each step) on constructed trajectories, by hand; the
step-sampled ones beside them keep their values."""

import dataclasses
import math

import numpy as np
import pytest

from crowdsim.distances import closest_approach, min_distance_between_steps
from crowdsim.metrics import ADDED_FIELDS, EpisodeMetrics, Trajectory, aggregate, episode_metrics
from tests.same_metrics import same_metrics


def make_traj(robot_pos, human_pos=None) -> Trajectory:
    """A trajectory of the given positions (``human_pos`` None: no humans), standing, goals never reached."""
    rp = np.asarray(robot_pos, dtype=float)
    hp = np.zeros((len(rp), 0, 2)) if human_pos is None else np.asarray(human_pos, dtype=float)
    return Trajectory(
        robot_positions=rp,
        robot_velocities=np.zeros_like(rp),
        human_positions=hp,
        human_velocities=np.zeros_like(hp),
        robot_goals=np.full((rp.shape[1], 2), 50.0),  # never reached
        human_goals=hp[-1],
        robot_accelerations=np.zeros((len(rp) - 1, rp.shape[1], 2)),
        dt=0.4,
        radius=0.3,
    )


@pytest.mark.parametrize(
    "start, end, expected",
    [
        ((-1.0, 1.0), (1.0, 1.0), 1.0),  # passes (0, 1) halfway
        ((-0.5, 0.0), (0.5, 0.0), 0.0),  # through each other
        ((1.0, 0.0), (2.0, 0.0), 1.0),  # moving away: the start is closest (s clipped to 0)
        ((2.0, 0.0), (1.0, 0.0), 1.0),  # approaching, not yet closest: the end (s clipped to 1)
        ((3.0, 4.0), (3.0, 4.0), 5.0),  # no relative motion
        ((-0.4, 0.7), (0.4, 0.7), 0.7),
    ],
)
def test_closest_approach_by_hand(start, end, expected):
    assert float(closest_approach(np.array(start), np.array(end))) == pytest.approx(expected, abs=1e-12)


def test_passing_through_each_other_between_two_steps():
    # Robot (-0.5, 0) -> (0.5, 0), human (0.5, 0) -> (-0.5, 0): 1.0 m apart at both states, 0 halfway.
    m = episode_metrics(make_traj([[[-0.5, 0.0]], [[0.5, 0.0]]], [[[0.5, 0.0]], [[-0.5, 0.0]]]))
    assert m.min_distance == 1.0 and not m.collision and not m.contact
    assert m.collision_steps == 0 and m.contact_steps == 0
    assert m.min_distance_between_steps == 0.0
    assert m.collision_between_steps and m.contact_between_steps


def test_an_offset_pass_is_a_collision_between_steps_but_no_contact():
    # Robot standing at 0; human (-0.4, 0.7) -> (0.4, 0.7): sqrt(0.16 + 0.49) = 0.806 m at both states
    # (no collision), 0.7 m halfway: a collision between steps (< 0.8 m), no contact (not < 0.6 m).
    m = episode_metrics(make_traj([[[0.0, 0.0]]] * 2, [[[-0.4, 0.7]], [[0.4, 0.7]]]))
    assert m.min_distance == pytest.approx(math.sqrt(0.65)) and not m.collision
    assert m.min_distance_between_steps == pytest.approx(0.7)
    assert m.collision_between_steps and not m.contact_between_steps


def test_every_robot_human_pair_and_step_at_once():
    # Robots at (0, 0) and (10, 0), standing. Human 1 passes robot 2: (9.5, 0.5) -> (10.5, 0.5) ->
    # (11.5, 0.5), relative to it (-0.5, 0.5) -> (0.5, 0.5) -> (1.5, 0.5): sqrt(0.5) = 0.707 m at the
    # states, 0.5 m at x = 10 in the first step. Human 2 stands 5 m north of robot 1.
    robots = [[[0.0, 0.0], [10.0, 0.0]]] * 3
    humans = [[[9.5, 0.5], [0.0, 5.0]], [[10.5, 0.5], [0.0, 5.0]], [[11.5, 0.5], [0.0, 5.0]]]
    m = episode_metrics(make_traj(robots, humans))
    assert m.min_distance == pytest.approx(math.sqrt(0.5)) and m.collision and not m.contact
    assert m.min_distance_between_steps == pytest.approx(0.5)
    assert m.collision_between_steps and m.contact_between_steps


def test_between_steps_equals_sampled_when_nobody_comes_closer_in_between():
    # The human walks straight away from the standing robot: the closest point is a recorded state.
    m = episode_metrics(make_traj([[[0.0, 0.0]]] * 3, [[[0.0, 0.7]], [[0.0, 1.1]], [[0.0, 1.5]]]))
    assert m.min_distance_between_steps == m.min_distance == pytest.approx(0.7)
    assert m.collision_between_steps == m.collision is True
    assert m.contact_between_steps == m.contact is False
    # one state only (no step): the state's distance
    assert min_distance_between_steps(np.zeros((1, 1, 2)), np.array([[[0.0, 2.0]]])) == 2.0


def test_exactly_d_min_or_twice_the_radius_between_steps_is_no_collision_or_contact():
    """As for the sampled flags, the thresholds are strict: a distance of exactly 0.8 m is no collision, of
    exactly 0.6 m no contact (though a collision)."""
    # Robot and human standing 0.8 m apart: 0.8 at both states and in between (no relative motion).
    m = episode_metrics(make_traj([[[0.0, 0.0]]] * 2, [[[0.8, 0.0]]] * 2))
    assert m.min_distance_between_steps == 0.8
    assert not m.collision_between_steps and not m.collision
    m = episode_metrics(make_traj([[[0.0, 0.0]]] * 2, [[[0.6, 0.0]]] * 2))
    assert m.min_distance_between_steps == 0.6
    assert m.collision_between_steps and not m.contact_between_steps and not m.contact


def test_without_humans_the_distance_is_inf_and_null_round_trips():
    alone = episode_metrics(make_traj([[[0.0, 0.0]], [[0.0, 1.0]]], np.zeros((2, 0, 2))))
    assert alone.min_distance_between_steps == math.inf
    assert not alone.collision_between_steps and not alone.contact_between_steps
    record = alone.as_dict()
    assert record["min_distance_between_steps"] is None  # JSON has no inf
    assert same_metrics(EpisodeMetrics.from_dict(record), alone)


def test_round_trip_and_older_records():
    m = episode_metrics(make_traj([[[-0.5, 0.0]], [[0.5, 0.0]]], [[[0.5, 0.0]], [[-0.5, 0.0]]]))
    assert same_metrics(EpisodeMetrics.from_dict(m.as_dict()), m)
    old = {k: v for k, v in m.as_dict().items() if k not in ADDED_FIELDS}
    rebuilt = EpisodeMetrics.from_dict(old)
    assert rebuilt.min_distance_between_steps is None
    assert rebuilt.collision_between_steps is None and rebuilt.contact_between_steps is None
    assert rebuilt.min_distance == 1.0 and rebuilt.collision_steps is None
    # the new fields go at the end (then robot contact's, added later): older records keep their order
    assert list(m.as_dict())[-7:-4] == [
        "min_distance_between_steps",
        "collision_between_steps",
        "contact_between_steps",
    ]


def test_aggregate_between_step_rates():
    through = episode_metrics(make_traj([[[-0.5, 0.0]], [[0.5, 0.0]]], [[[0.5, 0.0]], [[-0.5, 0.0]]]))
    offset = episode_metrics(make_traj([[[0.0, 0.0]]] * 2, [[[-0.4, 0.7]], [[0.4, 0.7]]]))
    far = episode_metrics(make_traj([[[0.0, 0.0]]] * 2, [[[0.0, 3.0]]] * 2))
    out = aggregate([through, offset, far, far])
    assert out["collision_rate"] == 0.0 and out["contact_rate"] == 0.0  # sampled: none
    assert (out["collision_between_steps_count"], out["collision_between_steps_rate"]) == (2, 50.0)
    assert (out["contact_between_steps_count"], out["contact_between_steps_rate"]) == (1, 25.0)
    old = EpisodeMetrics.from_dict({k: v for k, v in far.as_dict().items() if k not in ADDED_FIELDS})
    mixed = aggregate([through, old])
    assert math.isnan(mixed["collision_between_steps_rate"])
    assert math.isnan(mixed["contact_between_steps_count"])
    assert mixed["collision_rate"] == 0.0


def test_a_non_finite_position_shows_as_nan_whatever_the_order():
    """A segment to an infinite position has no closest approach: NaN, never silently the rows' minimum."""
    robots = np.array([[[0.0, 0.0]], [[np.inf, 0.0]], [[1.0, 0.0]]])
    humans = np.array([[[5.0, 0.0]], [[5.0, 0.0]], [[5.0, 0.0]]])
    with np.errstate(invalid="ignore"):  # inf - inf: numpy says so, the result says it too
        assert math.isnan(min_distance_between_steps(robots, humans))


def test_never_above_the_sampled_distance_even_by_rounding():
    # Robot standing at 0; human (0.3, 2.9) -> (0.7, 0.2), closest at the end state: |(0.7, 0.2)| =
    # 0.7280109889280517 m, while start + 1 * (end - start) rounds to 0.7280109889280518 m. The recorded
    # states count as they are, so the between-step distance is not the larger float (collision_between_steps
    # must hold whenever collision does).
    m = episode_metrics(make_traj([[[0.0, 0.0]]] * 2, [[[0.3, 2.9]], [[0.7, 0.2]]]))
    assert m.min_distance == pytest.approx(math.hypot(0.7, 0.2))
    assert m.min_distance_between_steps <= m.min_distance


def test_a_failed_episodes_metrics_compare_equal_however_their_nan_was_made():
    """A failed episode's travel_time is NaN: its records compare equal with tests.same_metrics, not with
    ``==`` (NaN != NaN; the dataclass's ``==`` gave True only for the very same NaN object, and on 3.13 not
    even then)."""
    m = episode_metrics(make_traj([[[0.0, 0.0]], [[0.0, 1.0]]], [[[3.0, 0.0]], [[3.0, 1.0]]]))
    assert not m.success and math.isnan(m.travel_time) and math.isnan(m.reach_times[0])
    other_nan = dataclasses.replace(m, travel_time=float("nan"), reach_times=(float("nan"),))
    assert other_nan != m and same_metrics(other_nan, m)
    assert same_metrics(EpisodeMetrics.from_dict(m.as_dict()), m)
    assert not same_metrics(dataclasses.replace(m, travel_time=1.0), m)
    assert not same_metrics(dataclasses.replace(m, reach_times=(1.0,)), m)
    assert not same_metrics(dataclasses.replace(m, n_steps=2), m)
