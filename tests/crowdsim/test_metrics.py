"""Episode metrics on constructed trajectories (numbers checkable on paper)."""

import math

import numpy as np
import pytest

from crowdsim.errors import SimulationError
from crowdsim.metrics import EpisodeMetrics, Trajectory, aggregate, episode_metrics, segments_intersect


def make_traj(
    robot_pos, human_pos, robot_vel=None, human_vel=None, robot_goals=None, success_rule="simultaneous"
):
    rp = np.asarray(robot_pos, dtype=float)
    hp = np.asarray(human_pos, dtype=float)
    return Trajectory(
        robot_positions=rp,
        robot_velocities=np.zeros_like(rp) if robot_vel is None else np.asarray(robot_vel, dtype=float),
        human_positions=hp,
        human_velocities=np.zeros_like(hp) if human_vel is None else np.asarray(human_vel, dtype=float),
        robot_goals=np.asarray(robot_goals if robot_goals is not None else rp[-1], dtype=float),
        human_goals=hp[-1],
        robot_accelerations=np.zeros((len(rp) - 1, rp.shape[1], 2)),
        dt=0.4,
        radius=0.3,
        success_rule=success_rule,
    )


P = np.array  # short alias for hand-written points


@pytest.mark.parametrize(
    "p1, q1, p2, q2, expected",
    [
        ((0, 0), (1.2, 0), (0.6, 1), (0.6, -1), True),  # proper crossing
        ((0, 0), (1.2, 0), (1.2, 1.2), (1.2, 0), True),  # end point touches end point
        ((0, 0), (1.2, 0), (0.6, 1.2), (0.6, 0), True),  # end point touches the middle
        ((0, 0), (1.2, 0), (1.2, 1.3), (1.2, 0.1), False),  # misses by 0.1 m
        ((0, 0), (1.2, 0), (2.0, 0), (0.8, 0), True),  # collinear, overlapping
        ((0, 0), (1.2, 0), (2.0, 0), (1.3, 0), False),  # collinear, apart
        ((0, 0), (1.2, 0), (0.5, 0), (0.5, 0), True),  # a standing agent on the path
        ((0, 0), (1.2, 0), (0.5, 0.1), (0.5, 0.1), False),  # a standing agent beside it
        ((0, 0), (0, 0), (0, 0), (0, 0), True),  # two standing agents at the same point
        # oblique paths: an axis-aligned one has a zero component, which hides a wrong cross product, and its
        # bounding box is the segment itself, which hides a collinearity test left out
        ((0, 0), (2, 2), (0, 2), (2, 0), True),  # crossing at (1, 1)
        ((0, 0), (2, 2), (0, 2), (0.9, 1.1), False),  # stops 0.14 m short of the diagonal
        ((0, 0), (2, 2), (1, 1), (1, 1), True),  # a standing agent on the diagonal
        ((0, 0), (2, 2), (1, 0.5), (1, 0.5), False),  # inside the diagonal's bounding box, off its line
    ],
)
def test_segments_intersect(p1, q1, p2, q2, expected):
    assert bool(segments_intersect(P(p1, float), P(q1, float), P(p2, float), P(q2, float))) is expected
    # symmetric in the two segments
    assert bool(segments_intersect(P(p2, float), P(q2, float), P(p1, float), P(q1, float))) is expected


def test_discomfort_from_projected_paths_that_just_touch():
    # Robot at 0 moving east at 1 m/s projects to (1.2, 0); a human at (1.2, 1.2) moving south at 1 m/s
    # projects to (1.2, 0): the paths touch at one step -> discomfort. A human 0.1 m further north misses.
    touching = make_traj(
        robot_pos=[[[0.0, 0.0]]],
        human_pos=[[[1.2, 1.2]]],
        robot_vel=[[[1.0, 0.0]]],
        human_vel=[[[0.0, -1.0]]],
    )
    m = episode_metrics(touching)
    assert m.discomfort and m.discomfort_steps == 1
    missing = make_traj(
        robot_pos=[[[0.0, 0.0]]],
        human_pos=[[[1.2, 1.3]]],
        robot_vel=[[[1.0, 0.0]]],
        human_vel=[[[0.0, -1.0]]],
    )
    assert not episode_metrics(missing).discomfort


def test_discomfort_length_scales_with_speed():
    # At 0.5 m/s the robot projects only 0.6 m: a human path crossing x = 0.7 is not reached; at 1 m/s it is.
    human_pos, human_vel = [[[0.7, 1.0]]], [[[0.0, -1.0]]]  # projects (0.7, 1.0) -> (0.7, -0.2)
    slow = make_traj([[[0.0, 0.0]]], human_pos, robot_vel=[[[0.5, 0.0]]], human_vel=human_vel)
    fast = make_traj([[[0.0, 0.0]]], human_pos, robot_vel=[[[1.0, 0.0]]], human_vel=human_vel)
    assert not episode_metrics(slow).discomfort
    assert episode_metrics(fast).discomfort


def test_collision_and_contact_thresholds():
    # Robot still at 0; a human passes at its closest 0.7 m (collision, no contact), another time 0.55 m.
    robot = [[[0.0, 0.0]]] * 3
    near = make_traj(robot, [[[2.0, 0.7]], [[0.0, 0.7]], [[-2.0, 0.7]]])
    m = episode_metrics(near)
    assert m.min_distance == pytest.approx(0.7)
    assert m.collision and not m.contact
    touching = make_traj(robot, [[[2.0, 0.55]], [[0.0, 0.55]], [[-2.0, 0.55]]])
    assert episode_metrics(touching).contact
    far = make_traj(robot, [[[2.0, 0.8]], [[0.0, 0.8]], [[-2.0, 0.8]]])  # exactly 0.8 is not below 0.8
    assert not episode_metrics(far).collision


def test_success_travel_time_and_path_length():
    # Two robots: one is within 0.3 m of its goal at row 2 (t = 0.8 s), the other at row 3 (t = 1.2 s).
    rp = [[[0, 0], [5, 0]], [[0, 1], [5, 0.5]], [[0, 1.8], [5, 1.0]], [[0, 2.0], [5, 1.8]]]
    traj = make_traj(rp, [[[9.0, 9.0]]] * 4, robot_goals=[[0.0, 2.0], [5.0, 2.0]])
    m = episode_metrics(traj)
    assert m.success and not m.timeout
    assert m.reach_times == (0.8, 1.2)
    assert m.travel_time == 1.2
    assert m.path_length == pytest.approx((2.0, 1.8))
    assert m.min_distance_robots == pytest.approx(5.0)
    assert m.n_steps == 3
    late = make_traj(rp[:3], [[[9.0, 9.0]]] * 3, robot_goals=[[0.0, 2.0], [5.0, 2.0]])
    m = episode_metrics(late)
    assert not m.success and m.timeout and math.isnan(m.travel_time) and math.isnan(m.reach_times[1])


def test_aggregate_rates_and_counts():
    rp = [[[0, 0]], [[0, 1.9]]]
    ok = episode_metrics(make_traj(rp, [[[3.0, 0.0]], [[3.0, 0.0]]], robot_goals=[[0.0, 2.0]]))
    hit = episode_metrics(make_traj(rp, [[[0.5, 0.0]], [[3.0, 0.0]]], robot_goals=[[0.0, 2.0]]))
    fail = episode_metrics(make_traj(rp, [[[3.0, 0.0]], [[3.0, 0.0]]], robot_goals=[[0.0, 5.0]]))
    out = aggregate([ok, hit, fail, ok])
    assert out["episodes"] == 4
    assert out["success_rate"] == 75.0 and out["success_count"] == 3
    assert out["collision_rate"] == 25.0 and out["contact_count"] == 1
    assert out["timeout_count"] == 1
    assert out["travel_time_mean"] == pytest.approx(0.4)
    assert out["min_distance_min"] == pytest.approx(0.5)
    # the closest episode first: the minimum is over every episode, the first one included (hit 0.5 m, ok 3 m)
    assert aggregate([hit, ok])["min_distance_min"] == pytest.approx(0.5)
    with pytest.raises(SimulationError, match="empty"):
        aggregate([])


def test_metrics_need_a_robot_and_serialise_to_json():
    with pytest.raises(SimulationError, match="n_robots=0"):
        episode_metrics(
            make_traj(np.zeros((2, 0, 2)), [[[0.0, 0.0]], [[1.0, 0.0]]], robot_goals=np.zeros((0, 2)))
        )
    m = episode_metrics(make_traj([[[0, 0]], [[0, 1]]], np.zeros((2, 0, 2)), robot_goals=[[0.0, 5.0]]))
    d = m.as_dict()
    assert d["min_distance"] is None and d["travel_time"] is None and d["reach_times"] == [None]


def test_success_rules_when_a_robot_reaches_then_leaves():
    # Goals (0, 2) and (5, 2). Robot 0 is inside at row 1, outside at row 2 (1 m off), inside again at row 3;
    # robot 1 is inside from row 2 on. first_reach: done at row 2 (0.8 s); simultaneous: only row 3 (1.2 s).
    rp = [[[0, 0], [5, 0]], [[0, 2.0], [5, 1.0]], [[0, 3.0], [5, 2.0]], [[0, 2.1], [5, 2.0]]]
    goals = [[0.0, 2.0], [5.0, 2.0]]
    humans = [[[9.0, 9.0]]] * 4
    first = episode_metrics(make_traj(rp, humans, robot_goals=goals, success_rule="first_reach"))
    both = episode_metrics(make_traj(rp, humans, robot_goals=goals, success_rule="simultaneous"))
    assert first.success and first.travel_time == 0.8
    assert both.success and both.travel_time == 1.2
    assert first.reach_times == both.reach_times == (0.4, 0.8)  # each robot's own first reach either way
    cut = make_traj(rp[:3], humans[:3], robot_goals=goals)  # ends before both are inside together
    assert episode_metrics(cut, success_rule="first_reach").success
    m = episode_metrics(cut)
    assert not m.success and m.timeout and math.isnan(m.travel_time) and m.reach_times == (0.4, 0.8)
    with pytest.raises(SimulationError, match="success_rule.*'sometimes'"):
        episode_metrics(cut, success_rule="sometimes")


def test_collision_and_contact_steps_count_states():
    # Robot still at 0; the human's distance at rows 0..5: 2.0, 0.7, 0.55, 0.79, 0.8, 0.6.
    # Below 0.8 m: rows 1, 2, 3, 5 -> 4 (0.8 exactly is not below); below 0.6 m: row 2 -> 1 (nor is 0.6).
    ys = [2.0, 0.7, 0.55, 0.79, 0.8, 0.6]
    m = episode_metrics(make_traj([[[0.0, 0.0]]] * 6, [[[0.0, y]] for y in ys]))
    assert m.collision_steps == 4 and m.contact_steps == 1
    assert m.min_distance == pytest.approx(0.55) and m.n_steps == 5
    alone = make_traj([[[0, 0]], [[0, 1]]], np.zeros((2, 0, 2)), robot_goals=[[0.0, 5.0]])
    no_humans = episode_metrics(alone)
    assert no_humans.collision_steps == 0 and no_humans.contact_steps == 0


def test_aggregate_step_frequencies_and_median():
    # a: 6 states, 4 collision, 1 contact (as above); b: 2 states, 1 collision (0.7 m at row 0), no contact.
    ys = [2.0, 0.7, 0.55, 0.79, 0.8, 0.6]
    a = episode_metrics(make_traj([[[0.0, 0.0]]] * 6, [[[0.0, y]] for y in ys]))
    b = episode_metrics(make_traj([[[0.0, 0.0]]] * 2, [[[0.0, 0.7]], [[0.0, 3.0]]]))
    out = aggregate([a, b])
    assert out["collision_step_freq"] == pytest.approx(100.0 * 5 / 8)
    assert out["contact_step_freq"] == pytest.approx(100.0 * 1 / 8)
    assert out["discomfort_step_freq"] == 0.0  # everyone stands still
    assert out["min_distance_median"] == pytest.approx((0.55 + 0.7) / 2)
    c = episode_metrics(make_traj([[[0.0, 0.0]]] * 2, [[[0.0, 0.9]], [[0.0, 3.0]]]))
    assert aggregate([a, b, c])["min_distance_median"] == pytest.approx(0.7)
    # an episode without a robot-human pair (a replayed crowd's, nobody tracked as the robots cross) is left
    # out, as a sweep's report leaves it: its inf made the mean inf and moved the median to (0.7 + 0.9) / 2
    alone = episode_metrics(make_traj([[[0.0, 0.0]]] * 2, np.zeros((2, 0, 2))))
    assert alone.min_distance == math.inf
    out = aggregate([a, b, c, alone])
    assert (out["min_distance_mean"], out["min_distance_median"], out["min_distance_min"]) == pytest.approx(
        ((0.55 + 0.7 + 0.9) / 3, 0.7, 0.55)
    )
    nobody = aggregate([alone, alone])
    assert (
        nobody["min_distance_mean"] == nobody["min_distance_median"] == nobody["min_distance_min"] == math.inf
    )


def test_from_dict_round_trip_and_old_records():
    ys = [2.0, 0.7, 0.55]
    m = episode_metrics(make_traj([[[0.0, 0.0]]] * 3, [[[0.0, y]] for y in ys], robot_goals=[[0.0, 9.0]]))
    back = EpisodeMetrics.from_dict(m.as_dict())
    assert back.as_dict() == m.as_dict() and math.isnan(back.travel_time)
    alone = episode_metrics(make_traj([[[0, 0]], [[0, 1]]], np.zeros((2, 0, 2)), robot_goals=[[0.0, 5.0]]))
    assert EpisodeMetrics.from_dict(alone.as_dict()).min_distance == math.inf  # null was "no pair"
    old = {k: v for k, v in m.as_dict().items() if k not in ("collision_steps", "contact_steps")}
    rebuilt = EpisodeMetrics.from_dict(old)
    assert rebuilt.collision_steps is None and rebuilt.discomfort_steps == m.discomfort_steps
    out = aggregate([m, rebuilt])
    assert math.isnan(out["collision_step_freq"]) and out["discomfort_step_freq"] == 0.0
    assert out["collision_rate"] == 100.0
    with pytest.raises(SimulationError, match="min_distance"):
        EpisodeMetrics.from_dict({k: v for k, v in old.items() if k != "min_distance"})


def test_a_null_flag_or_count_is_refused_not_read_as_nan():
    """A record's null success was NaN, which reads as true: a failed episode counted a success (only a hand
    edit or another writer makes one; a float's null stays NaN, a later field's None)."""
    m = episode_metrics(make_traj([[[0.0, 0.0]]] * 3, [[[0.0, 2.0]]] * 3, robot_goals=[[0.0, 9.0]]))
    for name, said in (("success", "true or false"), ("collision", "true or false"), ("n_steps", "a whole")):
        with pytest.raises(SimulationError, match=f"record's {name} is null, not {said}"):
            EpisodeMetrics.from_dict({**m.as_dict(), name: None})
    assert math.isnan(EpisodeMetrics.from_dict({**m.as_dict(), "travel_time": None}).travel_time)
    assert EpisodeMetrics.from_dict({**m.as_dict(), "robot_contact": None}).robot_contact is None


def test_a_robot_exactly_its_radius_from_its_goal_has_not_arrived():
    # Goal (0, 0), radius 0.3: the robot at (0.3, 0) is 0.3 m off, not strictly closer -> not inside under
    # either rule; one step on at (0.29, 0) it is (row 2, 0.8 s).
    rp = [[[1.0, 0.0]], [[0.3, 0.0]], [[0.29, 0.0]]]
    humans = [[[9.0, 9.0]]] * 3
    for rule in ("simultaneous", "first_reach"):
        edge = episode_metrics(make_traj(rp[:2], humans[:2], robot_goals=[[0.0, 0.0]], success_rule=rule))
        assert not edge.success and math.isnan(edge.reach_times[0])
        m = episode_metrics(make_traj(rp, humans, robot_goals=[[0.0, 0.0]], success_rule=rule))
        assert m.success and m.travel_time == 0.8 and m.reach_times == (0.8,)


def test_first_reach_needs_every_robot():
    # Robot 0 reaches its goal (0, 2) at row 1; robot 1 stays 2 m from its goal (5, 2): no success under
    # first_reach either, though one robot arrived.
    rp = [[[0, 0], [5, 0]], [[0, 2.0], [5, 0.0]]]
    m = episode_metrics(
        make_traj(rp, [[[9.0, 9.0]]] * 2, robot_goals=[[0.0, 2.0], [5.0, 2.0]], success_rule="first_reach")
    )
    assert not m.success and m.timeout and math.isnan(m.travel_time)
    assert m.reach_times[0] == 0.4 and math.isnan(m.reach_times[1])


def test_discomfort_steps_count_every_state():
    # Robot at 0 heading east at 1 m/s projects to (1.2, 0). The human at (0.6, 1.0) walks south at 1 m/s
    # at rows 0 and 1 (projects to (0.6, -0.2): crosses) and stands at row 2 (a point off the path): 2 states.
    m = episode_metrics(
        make_traj(
            [[[0.0, 0.0]]] * 3,
            [[[0.6, 1.0]]] * 3,
            robot_vel=[[[1.0, 0.0]]] * 3,
            human_vel=[[[0.0, -1.0]], [[0.0, -1.0]], [[0.0, 0.0]]],
            robot_goals=[[9.0, 9.0]],
        )
    )
    assert m.discomfort and m.discomfort_steps == 2
    assert aggregate([m])["discomfort_step_freq"] == pytest.approx(100.0 * 2 / 3)


def test_aggregate_travel_time_spread_distance_mean_and_path_length_over_robots():
    # a: success at row 1 (0.4 s), path 1.9 m, the standing human 3.0 m off at row 0.
    # b: success at row 2 (0.8 s), path 1.9 m, the human 0.5 m off at row 0.
    # c: two robots, goals never reached, paths 1.9 m and 0.9 m (mean 1.4 m), the human 1.0 m off robot 0.
    a = episode_metrics(make_traj([[[0, 0]], [[0, 1.9]]], [[[3.0, 0.0]]] * 2, robot_goals=[[0.0, 2.0]]))
    b = episode_metrics(
        make_traj([[[0, 0]], [[0, 1.0]], [[0, 1.9]]], [[[0.5, 0.0]]] * 3, robot_goals=[[0.0, 2.0]])
    )
    c = episode_metrics(
        make_traj(
            [[[0, 0], [5, 0]], [[0, 1.9], [5, 0.9]]], [[[1.0, 0.0]]] * 2, robot_goals=[[0.0, 9.0], [5.0, 9.0]]
        )
    )
    out = aggregate([a, b, c])
    # travel times 0.4 and 0.8 s: mean 0.6, population std (ddof 0) |0.4 - 0.6| = 0.2 (ddof 1 gives 0.283)
    assert out["travel_time_mean"] == pytest.approx(0.6)
    assert out["travel_time_std"] == pytest.approx(0.2)
    # minima 3.0, 0.5, 1.0: mean 1.5, median 1.0, min 0.5
    assert out["min_distance_mean"] == pytest.approx(1.5)
    assert out["min_distance_median"] == pytest.approx(1.0)
    assert out["min_distance_min"] == pytest.approx(0.5)
    # each episode's mean over its robots, then over episodes: (1.9 + 1.9 + 1.4) / 3
    assert out["path_length_mean"] == pytest.approx((1.9 + 1.9 + 1.4) / 3)


def test_human_human_minimum_and_the_discomfort_rate():
    # Two humans 1.5 m apart at row 0, 2.5 m at row 1; the robot 5 m off. With one human there is no pair.
    m = episode_metrics(
        make_traj(
            [[[0.0, -5.0]]] * 2, [[[0.0, 0.0], [1.5, 0.0]], [[0.0, 0.0], [2.5, 0.0]]], robot_goals=[[9, 9]]
        )
    )
    assert m.min_distance_humans == pytest.approx(1.5) and m.min_distance == pytest.approx(5.0)
    assert episode_metrics(make_traj([[[0.0, -5.0]]], [[[0.0, 0.0]]])).min_distance_humans == math.inf
    # the discomfort rate sits beside the others: 1 of 2 episodes (test_discomfort_... above: touching paths)
    touching = episode_metrics(
        make_traj([[[0.0, 0.0]]], [[[1.2, 1.2]]], robot_vel=[[[1.0, 0.0]]], human_vel=[[[0.0, -1.0]]])
    )
    out = aggregate([touching, m])
    assert (out["discomfort_count"], out["discomfort_rate"]) == (1, 50.0)


def test_the_thresholds_can_be_given():
    # A human standing 0.7 m from the robot: a collision at d_min 0.8 m, none at 0.6 m. A human 1.0 m ahead
    # on the robot's 1 m/s path is reached by the projected path at the 1.2 s horizon, not at 0.5 s.
    near = make_traj([[[0.0, 0.0]]], [[[0.0, 0.7]]], robot_goals=[[9.0, 9.0]])
    assert episode_metrics(near).collision
    assert not episode_metrics(near, collision_distance=0.6).collision
    ahead = make_traj([[[0.0, 0.0]]], [[[1.0, 0.0]]], robot_vel=[[[1.0, 0.0]]], robot_goals=[[9.0, 9.0]])
    assert episode_metrics(ahead).discomfort
    assert not episode_metrics(ahead, discomfort_horizon=0.5).discomfort


def test_the_mean_travel_time_is_a_mean():
    # successes at 0.4, 0.4 and 0.8 s: mean 1.6 / 3 = 0.533 s (the median would be 0.4 s)
    fast = episode_metrics(make_traj([[[0, 0]], [[0, 1.9]]], [[[3.0, 0.0]]] * 2, robot_goals=[[0.0, 2.0]]))
    slow = episode_metrics(
        make_traj([[[0, 0]], [[0, 1.0]], [[0, 1.9]]], [[[3.0, 0.0]]] * 3, robot_goals=[[0.0, 2.0]])
    )
    assert aggregate([fast, fast, slow])["travel_time_mean"] == pytest.approx(1.6 / 3)


@pytest.mark.parametrize("rule", ["simultaneous", "first_reach"])
def test_robots_that_start_on_their_goals_succeed_at_the_first_step_or_not_at_all(rule):
    """The simulator judges success after a step; the metrics counted the reset state, so a robot that
    started inside its goal and drove off read as a success in 0 s where the simulator said timeout."""
    goals = [[0.0, 0.0]]
    leaving = [[[0.25, 0.0]], [[0.6, 0.0]], [[1.0, 0.0]]]
    staying = [[[0.25, 0.0]], [[0.25, 0.0]], [[0.25, 0.0]]]
    humans = [[[9.0, 9.0]]] * 3
    left = episode_metrics(make_traj(leaving, humans, robot_goals=goals, success_rule=rule))
    stayed = episode_metrics(make_traj(staying, humans, robot_goals=goals, success_rule=rule))
    if rule == "simultaneous":
        assert not left.success
    else:  # reached at the reset, as the simulator's "has reached it at some point" has it
        assert left.success and left.travel_time == pytest.approx(0.4)
    assert stayed.success and stayed.travel_time == pytest.approx(0.4)


def test_an_episode_of_no_step_is_a_timeout_not_a_success():
    """One recorded state (0 steps), the robot on its goal: success is judged after a step, so none; the
    episode is a timeout (timeout is "not success"), with no travel time."""
    m = episode_metrics(make_traj([[[0.0, 0.0]]], [[[3.0, 0.0]]], robot_goals=[[0.0, 0.0]]))
    assert (m.n_steps, m.success, m.timeout) == (0, False, True)
    assert math.isnan(m.travel_time) and m.reach_times == (0.0,)
