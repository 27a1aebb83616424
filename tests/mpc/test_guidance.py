"""Guidance around standing humans (mpc/guidance.py), on layouts whose answer is known by hand."""

import numpy as np
import pytest

from mpc.config import MPCConfig
from mpc.guidance import (
    LOOKAHEAD,
    RING_NODES,
    RING_SCALE,
    _shortest_first_corner,
    guidance_targets,
    segment_distances,
)


def test_segment_distances_by_hand():
    a, b = np.array([0.0, 0.0]), np.array([4.0, 0.0])
    points = np.array([[2.0, 1.0], [-3.0, 4.0], [5.0, 0.0], [0.0, 0.0]])
    np.testing.assert_allclose(segment_distances(a, b, points), [[1.0, 5.0, 1.0, 0.0]])


def test_a_free_line_keeps_the_goal():
    positions, goals = np.array([[0.0, -5.0]]), np.array([[0.0, 5.0]])
    standing = np.array([[2.0, 0.0], [-2.0, 0.0]])  # 2 m either side of the line: clear at 1 m
    np.testing.assert_array_equal(guidance_targets(positions, goals, standing, 1.0), goals)
    np.testing.assert_array_equal(guidance_targets(positions, goals, np.zeros((0, 2)), 1.0), goals)


def test_a_row_across_the_line_is_walked_around_at_its_near_end():
    """A row of humans 1 m apart on y = 0 from x = -4 to x = 2 (discs of 0.9 m overlap: a wall). The robot at
    (0, -3) heads for (0, 3): the short way round is the row's right end, x = 2 + 0.9."""
    standing = np.stack([np.arange(-4.0, 2.5, 1.0), np.zeros(7)], axis=1)
    target = guidance_targets(np.array([[0.0, -3.0]]), np.array([[0.0, 3.0]]), standing, 0.9)[0]
    heading = target - [0.0, -3.0]
    assert heading[0] > 0 and np.linalg.norm(heading) >= LOOKAHEAD - 1e-9
    # Beyond Eq. 8's reach over the horizon (v_max H tau = 1.6 m), so the reference keeps moving at v_max.
    cfg = MPCConfig()
    assert np.linalg.norm(heading) > cfg.v_max * cfg.horizon * cfg.dt
    # The corner it heads for is the ring node past the right end: its line is clear of every disc.
    assert segment_distances(np.array([0.0, -3.0]), target, standing).min() >= 0.9 - 1e-9
    # The mirror image goes round the other end.
    mirrored = guidance_targets(np.array([[-2.0, -3.0]]), np.array([[-2.0, 3.0]]), standing * [-1, 1], 0.9)
    assert mirrored[0, 0] < -2.0


def test_no_detour_where_none_can_help_or_for_a_parked_robot():
    standing = np.array([[0.0, 0.0], [0.0, 3.0]])
    positions, goals = np.array([[0.0, -3.0], [0.2, -3.0]]), np.array([[0.0, 3.2], [0.2, 6.0]])
    targets = guidance_targets(positions, goals, standing, 0.9, active=np.array([True, False]))
    np.testing.assert_array_equal(targets, goals)  # robot 0's goal is inside a disc; robot 1 is not guided
    # A disc the robot already stands in does not block it from moving away.
    inside = guidance_targets(np.array([[0.0, -0.5]]), np.array([[0.0, -5.0]]), standing, 0.9)
    np.testing.assert_array_equal(inside, [[0.0, -5.0]])


@pytest.mark.parametrize("clearance", [0.0, -1.0])
def test_no_clearance_no_guidance(clearance):
    goals = np.array([[0.0, 3.0]])
    np.testing.assert_array_equal(
        guidance_targets(np.zeros((1, 2)), goals, np.array([[0.0, 1.0]]), clearance), goals
    )


def _dense_dijkstra_corner(start, goal, discs, clearance):
    """The first corner by the plain method: every edge of the visibility graph tested, Dijkstra from the
    goal. The graph is built as in mpc/guidance.py (RING_NODES nodes at RING_SCALE * clearance)."""
    angles = np.linspace(0.0, 2 * np.pi, RING_NODES, endpoint=False)
    ring = RING_SCALE * clearance * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    nodes = (discs[:, None, :] + ring[None]).reshape(-1, 2)
    nodes = nodes[np.linalg.norm(nodes[:, None] - discs[None], axis=-1).min(axis=1) >= clearance]
    nodes = np.concatenate([start[None], goal[None], nodes])
    n = len(nodes)
    weight = np.full((n, n), np.inf)
    for i in range(n):
        for j in range(n):
            if i != j and segment_distances(nodes[i], nodes[j], discs).min() >= clearance:
                weight[i, j] = np.linalg.norm(nodes[i] - nodes[j])
    dist, parent, done = np.full(n, np.inf), np.full(n, -1), np.zeros(n, dtype=bool)
    dist[1] = 0.0
    while not done.all():
        u = int(np.argmin(np.where(done, np.inf, dist)))
        if not np.isfinite(dist[u]):
            break
        done[u] = True
        better = dist[u] + weight[u] < dist
        dist[better], parent[better] = dist[u] + weight[u][better], u
    return None if parent[0] < 0 else nodes[parent[0]]


def test_the_lazy_search_finds_the_dense_searchs_corner():
    """A* with edges tested on demand (mpc/guidance.py) against Dijkstra on the fully tested graph, on random
    scenes whose straight line is blocked: the same first corner, or None for both."""
    rng = np.random.default_rng(3)
    compared = 0
    while compared < 25:
        discs = rng.uniform(-4.0, 4.0, (int(rng.integers(1, 9)), 2))
        start, goal, clearance = rng.uniform(-5.0, 5.0, 2), rng.uniform(-5.0, 5.0, 2), rng.uniform(0.6, 1.1)
        discs = discs[np.linalg.norm(discs - start, axis=1) >= clearance]
        if not len(discs) or segment_distances(start, goal, discs).min() >= clearance:
            continue
        compared += 1
        expected = _dense_dijkstra_corner(start, goal, discs, clearance)
        found = _shortest_first_corner(start, goal, discs, clearance)
        if expected is None:
            assert found is None
        else:
            np.testing.assert_allclose(found, expected, atol=1e-12)


def test_a_free_line_to_a_near_goal_keeps_the_goal_itself():
    # The goal 1 m away, nothing in between: the target is the goal, not a point prolonged to LOOKAHEAD
    # past it (which a detour's target would be).
    positions, goals = np.array([[0.0, 0.0]]), np.array([[0.0, 1.0]])
    standing = np.array([[3.0, 0.0]])
    np.testing.assert_array_equal(guidance_targets(positions, goals, standing, 1.0), goals)


def test_one_disc_is_passed_at_its_near_side_node_by_hand():
    """One human at the origin, clearance 1; the robot at (0.3, -5) heads for (0.3, 5). The ring node at angle
    0, (1.08, 0), sees both ends: the segment (0.3, -5) -> (1.08, 0) passes the origin at
    |0.3 * 5 + 5 * 0.78| / sqrt(0.78^2 + 25) = 5.4 / 5.06 = 1.067 m >= 1 (the same to the goal, by symmetry),
    while the next node round, (0.998, -0.413), is hidden from the goal (0.937 m). That corner is 5.06 m away,
    beyond LOOKAHEAD, so the target is the corner itself."""
    target = guidance_targets(np.array([[0.3, -5.0]]), np.array([[0.3, 5.0]]), np.array([[0.0, 0.0]]), 1.0)
    # 1.08 = RING_SCALE * clearance: the nodes sit 8 % outside the disc.
    np.testing.assert_allclose(target, [[1.08, 0.0]], atol=1e-12)


def test_a_disc_the_robot_stands_in_does_not_hide_the_others():
    # The robot stands 0.5 m from a human (inside its 0.9 m disc); another human blocks the line further on.
    # Only the first is ignored: the second is still walked around (a target off the x = 0 line).
    standing = np.array([[0.0, 0.0], [0.0, -3.0]])
    target = guidance_targets(np.array([[0.0, -0.5]]), np.array([[0.0, -6.0]]), standing, 0.9)[0]
    assert abs(target[0]) > 0.5
    assert segment_distances(np.array([0.0, -0.5]), target, standing[1:]).min() >= 0.9 - 1e-9


def test_a_disc_near_the_robot_but_not_around_it_still_blocks():
    # The robot 1.2 m from a human (outside its 0.9 m disc), the human straight between it and its goal:
    # only a disc the robot stands in is ignored, so this one is walked around.
    target = guidance_targets(np.array([[0.0, -1.2]]), np.array([[0.0, 4.0]]), np.array([[0.0, 0.0]]), 0.9)
    assert abs(target[0, 0]) > 0.5


def test_a_near_corner_is_prolonged_beyond_the_references_reach():
    # The robot 1.24 m from a human (clearance 1) that blocks its way: the first corner, on the ring just
    # outside the disc (1.05 m away), is nearer than v_max H tau = 1.6 m, so the target lies LOOKAHEAD along
    # that direction and Eq. 8's reference keeps moving at v_max over the whole horizon.
    start = np.array([0.3, -1.2])
    target = guidance_targets(start[None], np.array([[0.3, 5.0]]), np.array([[0.0, 0.0]]), 1.0)[0]
    cfg = MPCConfig()
    assert np.linalg.norm(target - start) == pytest.approx(LOOKAHEAD)
    assert LOOKAHEAD > cfg.v_max * cfg.horizon * cfg.dt


def test_a_prolonged_target_stops_where_its_line_would_enter_a_disc():
    """Eq. 8's reference stops on its target, so the target's line must clear every disc. The first corner
    (0.3 m off the robot) prolonged to LOOKAHEAD ran 0.21 m from the other human here; now it stops where its
    line touches that human's disc, and on random scenes no target's line enters a disc."""
    start, goal = np.array([1.8, 2.1]), np.array([0.2, -0.1])
    humans = np.array([[0.3, 2.0], [1.8, 1.2]])
    target = guidance_targets(start[None], goal[None], humans, 0.83)[0]
    assert segment_distances(start, target, humans)[0] == pytest.approx([0.83, 0.8808931], abs=1e-6)
    assert np.linalg.norm(target - start) < LOOKAHEAD
    rng = np.random.default_rng(5)
    guided = 0
    for _ in range(400):
        humans = rng.uniform(-3.0, 3.0, (int(rng.integers(2, 12)), 2))
        start, goal = rng.uniform(-4.0, 4.0, 2), rng.uniform(-4.0, 4.0, 2)
        target = guidance_targets(start[None], goal[None], humans, 0.83)[0]
        if np.array_equal(target, goal):
            continue
        guided += 1
        away = np.linalg.norm(humans - start, axis=1)
        radii = np.minimum(0.83, 0.99 * away)
        assert (segment_distances(start, target, humans)[0] >= radii - 1e-9).all()
    assert guided > 100


def test_a_robot_just_inside_a_disc_is_still_led_round_the_human():
    """The penalty's disc (1.018 m) sits where Eq. 11 holds a robot (about 1.05 m), so a robot is often just
    inside it. Dropping that disc sent a robot at 1.01 m straight at the human while one at 1.03 m was led
    round; the disc is now shrunk to just inside the robot, and both are led round."""
    clearance = MPCConfig(guidance_clearance="penalty").standing_clearance(0.03)
    human, goal = np.zeros((1, 2)), np.array([[0.0, 5.0]])
    for distance in (1.03, 1.01, 0.7):
        start = np.array([0.0, -distance])
        target = guidance_targets(start[None], goal, human, clearance)[0]
        assert segment_distances(start, target, human)[0, 0] >= 0.99 * min(distance, clearance) - 1e-9
        assert abs(target[0]) > 0.5


def test_a_long_horizons_target_lies_no_further_than_the_goal():
    """``lookahead`` grows with the horizon (6.4 m at 15 steps of 0.4 s at 1 m/s), but a target past the
    goal's distance would send the reference beyond a goal a short detour reaches: the target lies at most
    as far as the goal (at least LOOKAHEAD, Table I's prolongation, as before)."""
    from mpc.guidance import lookahead

    assert lookahead(1.0, 4, 0.4) == LOOKAHEAD  # Table I: exactly the constant
    reach = lookahead(1.0, 15, 0.4)
    assert reach == pytest.approx(6.4)
    start, human = np.array([0.3, -1.2]), np.array([[0.0, 0.0]])
    for goal_y, expected in ((2.0, 3.2), (3.5, 4.7), (9.0, 6.4)):
        goal = np.array([[0.3, goal_y]])
        target = guidance_targets(start[None], goal, human, 1.0, reach=reach)[0]
        assert np.linalg.norm(target - start) == pytest.approx(expected, abs=1e-9)
